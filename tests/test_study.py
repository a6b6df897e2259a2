"""rollcam study: the statistics of its report (fast), and the quick setting end to end (slow)."""

from __future__ import annotations

import dataclasses
import json

import pytest
from rollcam.host.cli import main
from rollcam.host.training.study import plan_jobs
from rollcam.host.training.study_report import aggregate, difference, report_markdown, statements
from rollcam.host.training.study_settings import MEDIUM, QUICK, REDUCED


def _result(key, group, speed, train, seed, test, **kw):
    job = {"key": key, "group": group, "speed": speed, "train": list(train), "seed": seed, "raw": False,
           "scenes": None, "cameras": None} | kw
    return {"job": job, "test": test}


def _test(gs, rs):
    cell = lambda v: {"P": v, "R": v, "mAP50": v, "mAP50_95": v / 2}  # noqa: E731
    return {"gs": cell(gs), "rs": cell(rs), "gsrs": cell((gs + rs) / 2)}


def test_difference_is_flagged_only_beyond_twice_its_standard_error():
    gs = {"mean": 0.80, "std": 0.01, "n": 3}
    assert difference(gs, {"mean": 0.70, "std": 0.01, "n": 3})["beyond_spread"] is True
    small = difference(gs, {"mean": 0.79, "std": 0.02, "n": 3})
    assert small["beyond_spread"] is False and small["relative"] == pytest.approx(-0.0125)


def test_plan_has_three_seeds_per_headline_cell_and_no_duplicate_runs():
    for s in (QUICK, REDUCED):
        jobs = plan_jobs(s)
        assert len({j.key for j in jobs}) == len(jobs)
        cells = {}
        for j in jobs:
            if j.group != "fig4":
                cells.setdefault((j.group, j.train, j.raw), set()).add(j.seed)
        assert all(len(seeds) >= 3 for seeds in cells.values())
    assert {j.speed for j in plan_jobs(REDUCED) if j.group == "speed"} == {"5", "20"}


def test_aggregate_tables_and_plain_answers():
    s = QUICK
    results = []
    for seed, (g, r) in enumerate([(0.80, 0.79), (0.81, 0.80), (0.79, 0.78)]):
        for sp in ("normal", "fast"):
            gs, rs = (g, r) if sp == "normal" else (g, r - 0.2)
            results.append(_result(f"{sp}_gs_s{seed}", "t1", sp, (f"{sp}_gs",), seed, _test(gs, gs - 0.3)))
            results.append(_result(f"{sp}_rs_s{seed}", "t1", sp, (f"{sp}_rs",), seed, _test(rs - 0.1, rs)))
    agg = aggregate(s, results)
    normal = agg["table1"]["normal"]
    assert normal["gs"]["mAP50"]["mean"] == pytest.approx(0.80)
    assert normal["rs"]["mAP50"]["mean"] == pytest.approx(0.79)
    assert normal["gs_to_rs"]["mAP50"]["beyond_spread"] is False
    assert agg["table1"]["fast"]["gs_to_rs"]["mAP50"]["beyond_spread"] is True
    assert agg["table3"]["normal"]["GS"]["rs"]["mAP50"]["mean"] == pytest.approx(0.50)
    text = statements(agg)
    assert any("1x (normal)" in t and "-1.2%: within 2 %" in t for t in text)
    assert any("10x (fast)" in t and "NOT within 2 %" in t and "beyond" in t for t in text)
    one = statements(aggregate(s, [r for r in results if r["job"]["seed"] == 0]))
    assert all("one seed so far: no spread to judge by" in t and "within the" not in t for t in one)

    # the report people read: what a setting with a base says about its start, and no empty sections
    timing = {"train_s_sum": 3600.0, "workers": 0, "finished": 7, "planned": 41}
    md = report_markdown(s, agg, timing, "rollcam study --quick --out q")
    assert "trained from scratch for 2 epochs" in md and "## Table 1 analogue" in md
    assert "## Fig. 4 analogue" not in md and "## RS penalty" not in md  # no Fig. 4 or raw runs finished
    base = _result("base", "base", "normal", ("normal_gs",), 0, _test(0.6, 0.6))
    for cell in base["test"].values():
        cell["mAP50_95_se"] = 0.004
    medium = dataclasses.replace(MEDIUM, seeds=(0, 1, 2))
    md = report_markdown(medium, aggregate(medium, [*results, base]), timing, "rollcam study --setting medium")
    assert "fine-tuned for 12 epochs per run from one base model (24 epochs on the GS images of 800 pairs" in md
    assert "The base model every run starts from" in md and "GS mAP@0.5 0.600, mAP@0.5:0.95 0.300" in md
    assert "(7 of 41; 1.00 h of training" in md
    assert "## Table 3 analogue" in md  # the GS models tested on RS images and the RS models on GS ones
    assert "## RS penalty" not in md and "## Fig. 4" not in md  # no speeds beyond Table 1's, no Fig. 4 runs


@pytest.mark.parametrize("command", ["study", "dataset"])
@pytest.mark.parametrize("where", ["file", "below-a-file"])
def test_out_that_is_a_file_is_one_line_exit_2(tmp_path, capsys, command, where):
    """Issue 37: ``study --out FILE`` (and ``dataset``) ended in a raw [Errno 17] / [Errno 20] with exit 1 on main."""
    (tmp_path / "f").write_text("x")
    out = tmp_path / "f" if where == "file" else tmp_path / "f" / "sub"
    args = ["study", "--quick"] if command == "study" else ["dataset", "--frames", "6", "--scenes", "3"]
    assert main([*args, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("rollcam: error: --out ") and str(out) in err[-1] and "Errno" not in err[-1], err
    assert sum(line.startswith("rollcam: error:") for line in err) == 1
    assert (tmp_path / "f").read_text() == "x"


@pytest.mark.slow
def test_quick_study_end_to_end(tmp_path, capsys):
    pytest.importorskip("torch")
    out = tmp_path / "study"
    assert main(["study", "--quick", "--out", str(out), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert len(doc["runs"]) == len(plan_jobs(QUICK))
    for name in ("report.md", "report.json", "report.png"):
        assert (out / name).is_file()
    assert set(doc["table1"]) == {"normal", "fast"} and "raw" in doc and doc["fig4"]["scenes"]
    assert all(len(row["gs"]["mAP50"]["values"]) == 3 for row in doc["table1"].values())
    # a rerun finds every run finished and rewrites the same tables
    assert main(["study", "--quick", "--out", str(out), "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert again["table1"] == doc["table1"]
