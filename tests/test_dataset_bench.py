"""The dataset bench runs end to end (tiny size; its speed targets are judged by ``rollcam bench dataset``)."""

from __future__ import annotations

from rollcam.benchmarks.dataset import bench_dataset, format_report, synthetic_eval_inputs


def test_bench_dataset_small():
    doc = bench_dataset((192, 108), pairs=6, scale_pairs=6, rounds=1)
    assert set(doc["targets"]) == {"generation_overhead", "two_worker_speedup", "metrics_1000_images_s"}
    assert doc["generation_s"] > 0 and doc["bare_s"] > 0 and doc["bytes_per_pair"] > 0
    assert "targets:" in format_report(doc)
    truths, dets = synthetic_eval_inputs(50)
    assert len(truths) == len(dets) == 50
