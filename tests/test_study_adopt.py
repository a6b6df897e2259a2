"""A study carried on elsewhere from its report: ``rollcam study --adopt`` takes finished runs over only when they
are of the same setting, were tested on byte-identical datasets and share the base model (fast)."""

from __future__ import annotations

import dataclasses
import json
import re

import pytest
from rollcam.common.errors import ConfigError
from rollcam.host.cli import main
from rollcam.host.training.study import BASE_WEIGHTS, adopt, dataset_digests, export_base, weights_digest
from rollcam.host.training.study_settings import QUICK

WITH_BASE = dataclasses.replace(QUICK, base_frames=8, base_scenes=6, base_epochs=2, base_lr=4e-3)


def _dataset(root, name="rgb", sha="ab" * 32):
    """A study folder's dataset as ``dataset_digests`` reads it: the card and one sample record."""
    data = root / "data" / name
    (data / "records" / "normal").mkdir(parents=True)
    (data / "dataset.json").write_text("{}")
    rec = {"files": {"normal_rs/images/test/a.png": {"bytes": 10, "sha256": sha}}}
    (data / "records" / "normal" / "s000_noon_c0.json").write_text(json.dumps(rec))


def _run(key, map_=0.5):
    return {"job": {"key": key}, "test": {"rs": {"mAP50_95": map_}}, "train_s": 1.0, "test_s": 0.5, "val": None}


def _report(where, s, root, runs, **more):
    where.mkdir(parents=True, exist_ok=True)
    doc = {"kind": "rollcam-study", "settings": s.to_json(), "datasets": dataset_digests(s, root),
           "runs": runs} | more
    (where / "report.json").write_text(json.dumps(doc))
    return where


def test_adopt_takes_over_finished_runs_and_table_2_and_keeps_its_own(tmp_path):
    mine, there = tmp_path / "here", tmp_path / "there"
    _dataset(mine)
    _dataset(there)
    rep = _report(tmp_path / "copy", QUICK, there, [_run("fast_rs_s0", 0.4), _run("fast_gs_s0", 0.6)],
                  coco={"ssdlite": {"normal": {"gs": {"mAP50": 0.3}}, "spec": "ssdlite?conf=0.01"}})
    (mine / "runs" / "fast_gs_s0").mkdir(parents=True)
    (mine / "runs" / "fast_gs_s0" / "test.json").write_text(json.dumps(_run("fast_gs_s0", 0.9)))
    assert adopt(QUICK, mine, rep) == ["fast_rs_s0"]
    assert json.loads((mine / "runs" / "fast_rs_s0" / "test.json").read_text())["test"]["rs"]["mAP50_95"] == 0.4
    assert json.loads((mine / "runs" / "fast_gs_s0" / "test.json").read_text())["test"]["rs"]["mAP50_95"] == 0.9
    assert json.loads((mine / "coco" / "ssdlite.json").read_text()) == {"normal": {"gs": {"mAP50": 0.3}}}
    assert adopt(QUICK, mine, rep / "report.json") == []  # the file itself names the report too; nothing new


def test_adopt_refuses_other_settings_other_datasets_unknown_runs_and_itself(tmp_path):
    mine, there = tmp_path / "here", tmp_path / "there"
    _dataset(mine)
    _dataset(there, sha="cd" * 32)
    other = dataclasses.replace(QUICK, epochs=3)
    with pytest.raises(ConfigError, match=r"other settings \(epochs: 3 there, 2 here\)"):
        adopt(QUICK, mine, _report(tmp_path / "a", other, mine, [_run("fast_rs_s0")]))
    theirs, here = dataset_digests(QUICK, there)["rgb"], dataset_digests(QUICK, mine)["rgb"]
    assert theirs != here
    with pytest.raises(ConfigError, match=f"another 'rgb' dataset .*{theirs[:12]} there, {here[:12]} here"):
        adopt(QUICK, mine, _report(tmp_path / "b", QUICK, there, [_run("fast_rs_s0")]))
    with pytest.raises(ConfigError, match="records no dataset digests"):
        adopt(QUICK, mine, _report(tmp_path / "c", QUICK, mine, [_run("fast_rs_s0")], datasets={}))
    # a run the setting does not have (or a path in disguise) refuses the whole report: nothing is half-taken
    for key in ("fast_rs_s9", "../../escape"):
        with pytest.raises(ConfigError, match=re.escape(f"{key!r} is not a run of the 'quick' setting")):
            adopt(QUICK, mine, _report(tmp_path / "e", QUICK, mine, [_run("fast_rs_s0"), _run(key)]))
        assert not (mine / "runs").exists() and not (tmp_path / "escape").exists()
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "report.json").write_text("{\"kind\": \"rollcam-dataset\"}")
    for bad, what in ((tmp_path / "nowhere", "no readable study report"), (tmp_path / "d", "not a rollcam study")):
        with pytest.raises(ConfigError, match=what):
            adopt(QUICK, mine, bad)
    _report(mine, QUICK, mine, [_run("fast_rs_s0")])
    with pytest.raises(ConfigError, match="is --out itself"):
        adopt(QUICK, mine, mine)


def test_adopt_takes_only_runs_of_datasets_verified_here(tmp_path):
    mine = tmp_path / "here"
    _dataset(mine)
    raw = _run("raw_fast_rs_s0")
    raw["job"]["raw"] = True
    digests = dataset_digests(QUICK, mine) | {"raw": "ef" * 32}  # raw was built there, not here
    rep = _report(tmp_path / "copy", QUICK, mine, [_run("fast_rs_s0"), raw], datasets=digests)
    assert adopt(QUICK, mine, rep) == ["fast_rs_s0"]
    assert not (mine / "runs" / "raw_fast_rs_s0").exists()


def test_adopt_carries_the_base_weights_the_report_names_and_refuses_another_base(tmp_path):
    torch = pytest.importorskip("torch")
    mine = tmp_path / "here"
    _dataset(mine)
    ones = {"w": torch.ones(3)}
    rep = _report(tmp_path / "copy", WITH_BASE, mine, [_run("base"), _run("fast_rs_s0")],
                  base_sha256=weights_digest(ones))
    with pytest.raises(ConfigError, match="does not carry it"):
        adopt(WITH_BASE, mine, rep)
    only_base = _report(tmp_path / "base-only", WITH_BASE, mine, [_run("base")], base_sha256=weights_digest(ones))
    with pytest.raises(ConfigError, match="does not carry it"):
        adopt(WITH_BASE, mine, only_base)
    torch.save({"w": torch.zeros(3)}, rep / BASE_WEIGHTS)  # another base than the one its runs started from
    with pytest.raises(ConfigError, match="is not the base its runs were fine-tuned from"):
        adopt(WITH_BASE, mine, rep)
    assert not (mine / "runs").exists()
    torch.save({"model": ones, "step": 3}, rep / BASE_WEIGHTS)  # a whole checkpoint is read for its weights
    assert adopt(WITH_BASE, mine, rep) == ["base", "fast_rs_s0"]
    assert torch.equal(torch.load(mine / "runs" / "base" / "last.pt")["model"]["w"], torch.ones(3))

    # a folder whose own base finished differently: its runs and the report's are not one study
    other = tmp_path / "other"
    _dataset(other)
    (other / "runs" / "base").mkdir(parents=True)
    (other / "runs" / "base" / "test.json").write_text(json.dumps(_run("base")))
    torch.save({"model": {"w": torch.zeros(3)}, "step": 7}, other / "runs" / "base" / "last.pt")
    with pytest.raises(ConfigError, match="another base model"):
        adopt(WITH_BASE, other, rep)
    torch.save({"model": ones, "step": 7}, other / "runs" / "base" / "last.pt")
    assert adopt(WITH_BASE, other, rep) == ["fast_rs_s0"]

    # what the report folder carries: the base checkpoint's model weights, written afresh each time
    assert export_base(WITH_BASE, other) == weights_digest(ones)
    torch.save({"w": torch.full((3,), 7.0)}, other / BASE_WEIGHTS)  # a stale or foreign file is replaced
    assert export_base(WITH_BASE, other) == weights_digest(ones)
    assert torch.equal(torch.load(other / BASE_WEIGHTS)["w"], torch.ones(3))
    assert export_base(QUICK, other) is None


def test_cli_adopt_of_a_missing_report_is_one_line_exit_2(tmp_path, capsys):
    pytest.importorskip("torch")
    out = tmp_path / "s"
    _dataset(out)
    assert main(["study", "--quick", "--report", "--out", str(out), "--adopt", str(tmp_path / "nothing")]) == 2
    err = [line for line in capsys.readouterr().err.strip().splitlines() if line.startswith("rollcam: error:")]
    assert len(err) == 1 and "--adopt" in err[0] and "nothing" in err[0]
