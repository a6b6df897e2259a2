"""``rollcam bench detect`` pieces on small inputs (the speed targets themselves live in the bench)."""

from __future__ import annotations

import json

from rollcam.benchmarks.detect import detector_times, loop_overhead
from rollcam.host.cli import main


def test_loop_overhead_and_detector_times_report_their_fields():
    o = loop_overhead(frames=2, uri="emu:imx219?size=320x180&seed=0")
    assert o["frames"] == 2 and o["capture_ms_median"] > 0 and o["bookkeeping_ms_median"] >= 0
    rows = detector_times(("ssdlite",), sizes=((320, 180),), repeats=1)
    assert rows[0]["detector"] == "ssdlite" and rows[0]["ms_median"] > 0


def test_bench_detect_is_wired(tmp_path, monkeypatch, capsys):
    import rollcam.benchmarks.detect as mod

    monkeypatch.setattr(mod, "loop_overhead", lambda frames: {"uri": "u", "frames": frames, "capture_ms_median": 1.0,
                                                              "bookkeeping_ms_median": 0.5, "bookkeeping_ms_p95": 0.6,
                                                              "target_bookkeeping_ms": 5.0, "meets_target": True})
    monkeypatch.setattr(mod, "detector_times", lambda specs, repeats: [
        {"detector": s, "width": 8, "height": 8, "ms_median": 1.0, "detections": 0} for s in specs])
    assert main(["bench", "detect", "--quick", "--out", str(tmp_path), "--onnx", "m.onnx", "--check"]) == 0
    assert "bookkeeping 0.50 ms/frame" in capsys.readouterr().out
    doc = json.loads((tmp_path / "detect_bench.json").read_text())
    assert doc["detectors"][-1]["detector"] == "onnx:m.onnx" and doc["loop_overhead"]["frames"] == 5
