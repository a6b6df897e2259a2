"""The bench machinery (``rollcam bench STUDY``) on a tiny frame: schema, error ordering, plot, the study
command line and ``--check``. No timing checks."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
from rollcam.benchmarks import bench, render_cases
from rollcam.benchmarks.render_report import format_table
from rollcam.benchmarks.studies import STUDIES, missed
from rollcam.common.errors import ConfigError
from rollcam.host.cli import main

ROW_KEYS = {"method", "scene", "ms_per_frame", "cpu_ms_per_frame", "mean_abs_err_dn", "max_abs_err_dn",
            "max_box_err_px", "x_memcpy", "x_memcpy_cold", "x_memcpy_cpu", "x_memcpy_cold_cpu", "speedup_vs_reference",
            "kind", "n_timed", "note"}


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, object]:
    out = tmp_path_factory.mktemp("bench")
    doc = bench.run_bench(width=192, height=108, quick=True, out_dir=out, scenes=("fast_ego",),
                          bands=(1, 2, 4, 8, 16, 64), footage_fps=(240, bench.LINE_RATE), footage_scenes=None,
                          full_reference=True, n_frames=2, compose_repeats=1, memcpy_repeats=10,
                          scaling_sizes=((64, 36), (128, 72)), scaling_walkers=(0, 3), scaling_frames=1)
    return doc, out


def test_json_document_has_rows_floor_targets_machine(tiny) -> None:
    doc, out = tiny
    assert {"rows", "floor", "targets", "machine"} <= set(doc)
    methods = {r["method"] for r in doc["rows"]}
    assert {"reference", "exact", "gs", "banded_1", "banded_64", "footage_240_nearest", "footage_240_linear",
            "footage_240_flow", "footage_3240_nearest", "footage_3240_flow"} <= methods
    for row in doc["rows"]:
        assert set(row) >= ROW_KEYS, row["method"]
        assert row["ms_per_frame"] > 0 and row["x_memcpy"] > 0 and row["speedup_vs_reference"] > 0
    assert doc["floor"]["ms"] > 0 and doc["floor"]["bytes"] == 192 * 108 * 3
    for target in doc["targets"].values():
        assert {"value", "limit", "pass", "per_scene"} <= set(target)
    on_disk = json.loads((out / "bench.json").read_text())
    assert on_disk["rows"] == doc["rows"]


def test_scaling_table_times_every_camera_size_and_walker_count_and_fits_them(tiny) -> None:
    doc, _ = tiny
    rows = doc["scaling"]["rows"]
    assert {(r["camera"], r["size"], r["walkers"]) for r in rows} == {
        (c, s, n) for c in ("static", "moving") for s in ("64x36", "128x72") for n in (0, 3)}
    assert all(r["ms_per_frame"] > 0 for r in rows)
    fits = doc["scaling"]["fits"]
    assert set(fits["vs_pixels"]) == {f"{c}, {n} walkers" for c in ("static", "moving") for n in (0, 3)}
    assert all(f is not None and "b" in f for f in fits["vs_pixels"].values())
    assert "scaling (exact RS" in format_table(doc)


def test_exact_and_line_rate_footage_equal_the_reference(tiny) -> None:
    doc, _ = tiny
    rows = {r["method"]: r for r in doc["rows"]}
    assert "reference image" in doc["baseline"]
    assert rows["exact"]["mean_abs_err_dn"] == 0 and rows["exact"]["max_abs_err_dn"] == 0
    assert rows["exact"]["max_box_err_px"] == 0
    assert rows["reference"]["max_box_err_px"] == 0
    # At the line rate every line is a footage frame: the study's method under every compose method.
    for method in ("nearest", "linear", "flow"):
        assert rows[f"footage_3240_{method}"]["max_abs_err_dn"] <= 1
    assert doc["targets"]["exact_vs_reference_max_abs_diff"]["pass"] is True


def test_banded_error_falls_as_bands_grow(tiny) -> None:
    doc, _ = tiny
    rows = {r["method"]: r for r in doc["rows"]}
    errs = [rows[f"banded_{k}"]["mean_abs_err_dn"] for k in (1, 2, 4, 8, 16, 64)]
    assert errs[0] > 0
    assert all(b <= a for a, b in itertools.pairwise(errs)), errs
    assert errs[-1] < errs[0] / 4


def test_plot_is_written(tiny) -> None:
    _, out = tiny
    png = (out / "bench.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 1000


def test_banded_times_hold_each_band_at_its_middle() -> None:
    t = np.arange(8, dtype=np.int64) * 10
    assert render_cases.banded_times_ns(t, 1).tolist() == [35] * 8
    assert render_cases.banded_times_ns(t, 2).tolist() == [15] * 4 + [55] * 4
    assert render_cases.banded_times_ns(t, 8).tolist() == t.tolist()
    assert render_cases.banded_times_ns(t, 100).tolist() == t.tolist()


def test_quick_config_and_bad_options(capsys) -> None:
    cfg = bench.make_config(quick=True)
    assert cfg.quick and not cfg.full_reference and cfg.flow_preset == "fast" and cfg.flow_margin_px == 48
    with pytest.raises(ConfigError, match="scenes"):
        bench.make_config(scenes=("rainy",))
    with pytest.raises(ConfigError, match="unknown bench option"):
        bench.make_config(colour="red")
    assert main(["bench", "render", "--quick", "--scenes", "rainy", "--out", "unused"]) == 2
    assert "rollcam: error: bench scenes" in capsys.readouterr().err


def _fake(doc: dict):
    return lambda *a, **k: doc


DATASET_DOC = {"size": "8x8", "targets": {
    "generation_overhead": {"value": 1.2, "op": "<=", "limit": 1.5, "pass": True},
    "two_worker_speedup": {"value": 1.1, "op": ">=", "limit": 1.7, "pass": False}}}


def test_bench_dataset_runs_the_dataset_study_only(tmp_path, monkeypatch, capsys) -> None:
    import rollcam.benchmarks.dataset as ds

    monkeypatch.setattr(ds, "bench_dataset", _fake(DATASET_DOC))
    monkeypatch.setattr(ds, "format_report", lambda doc: "dataset report")
    monkeypatch.setattr(bench, "run_bench", lambda *a, **k: pytest.fail("the render study ran too"))
    assert main(["bench", "dataset", "--out", str(tmp_path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == DATASET_DOC
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dataset_bench.json"]  # no bench.json / bench.png
    assert main(["bench", "dataset", "--out", str(tmp_path)]) == 0
    assert capsys.readouterr().out == "dataset report\n"


def test_check_exits_1_naming_each_missed_target(tmp_path, monkeypatch, capsys) -> None:
    import rollcam.benchmarks.dataset as ds

    monkeypatch.setattr(ds, "bench_dataset", _fake(DATASET_DOC))
    monkeypatch.setattr(ds, "format_report", lambda doc: "dataset report")
    assert main(["bench", "dataset", "--out", str(tmp_path), "--json", "--check"]) == 1
    captured = capsys.readouterr()
    assert json.loads(captured.out) == DATASET_DOC  # the document is printed all the same
    assert captured.err == ("rollcam: error: bench dataset: 1 target(s) missed: two_worker_speedup (1.1 >= 1.7 "
                            "failed)\n")
    passing = {**DATASET_DOC, "targets": {"generation_overhead": DATASET_DOC["targets"]["generation_overhead"]}}
    monkeypatch.setattr(ds, "bench_dataset", _fake(passing))
    assert main(["bench", "dataset", "--out", str(tmp_path), "--check"]) == 0


def test_every_study_reads_its_targets_in_one_shape(tiny) -> None:
    doc, _ = tiny
    targets = STUDIES["render"].targets(doc)
    assert set(targets) == set(doc["targets"])
    for t in targets.values():
        assert set(t) == {"value", "op", "limit", "pass"}
    ptc = STUDIES["ptc"].targets({"errors": {"gain": 0.01, "read_noise": -0.2}})
    assert ptc["gain_error"]["pass"] is True and ptc["read_noise_error"]["pass"] is False
    assert missed(ptc) == ["read_noise_error (-0.2 |x| <= 0.05 failed)"]
    def realism(ssd, hog):
        return STUDIES["realism"].targets({"detectors": {
            "ssdlite?tiles=3x2": {"at_precision_0.8": None if ssd is None else {"recall": ssd}},
            "hog": {"at_default": {"recall": hog}}}})
    t = realism(0.75, 0.4)
    assert t["ssdlite recall at P>=0.8"]["pass"] is True and t["hog recall"]["pass"] is False
    t = realism(None, None)  # precision never reaches 0.8 / no walker to find: n/a
    assert t["ssdlite recall at P>=0.8"]["pass"] is None and t["hog recall"]["pass"] is None


def test_soak_refuses_a_non_positive_duration() -> None:
    from rollcam.benchmarks.soak import run_soak

    with pytest.raises(ConfigError, match="minutes"):
        run_soak(-1)


def test_device_study_times_reads_and_names_each_miss_with_its_cause(tmp_path, capsys) -> None:
    rows = "static_bgr3,static_yuyv_noblur,night_steady,night_lights"
    args = ["bench", "device", "--size", "64x36", "--quick", "--frames", "1", "--rows", rows, "--out", str(tmp_path)]
    assert main([*args, "--json", "--check"]) == 1  # a 64x36 frame is far more than 8 copies of itself
    captured = capsys.readouterr()
    doc = json.loads(captured.out)
    assert list(doc["rows"]) == rows.split(",")
    assert all(r["wall_ms"] > 0 and r["uri"].startswith("emu:imx219?size=64x36") for r in doc["rows"].values())
    assert set(doc["targets"]) == {"static_rs_x_copy", "sensor_stages_vs_clean", "night_lights_x_steady"}
    miss = doc["targets"]["static_rs_x_copy"]
    assert miss["pass"] is False and miss["cause"]["static_bgr3"][0]["ms"] >= 0
    assert "static_rs_x_copy" in captured.err and (tmp_path / "device.json").exists()
    assert main(["bench", "device", "--rows", "ego_moon", "--out", str(tmp_path)]) == 2
    assert "rollcam: error: --rows: 'ego_moon'" in capsys.readouterr().err
