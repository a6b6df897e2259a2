"""rollcam dataset: plan, exact labels, byte-identical output whatever the executor, resume after interruption."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from rollcam.common.errors import ConfigError
from rollcam.host.cli import main
from rollcam.host.datasets import DatasetConfig, build_dataset, make_plan
from rollcam.host.datasets.build import DRIVER_LOCK
from rollcam.host.datasets.layout import content_digest
from rollcam.host.datasets.plan import LabelPolicy
from rollcam.host.datasets.sample import read_records
from rollcam.host.sources import open_camera

SMALL = DatasetConfig(size=(192, 108), scenes=3, frames=6, pedestrians=12, seed=7)


def _tree(root: Path, pattern: str = "*") -> dict[str, bytes]:
    """Label-bearing files of a dataset (labels, COCO, card, records) by relative path."""
    keep = (".txt", ".json", ".yaml", ".md")
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob(pattern))
            if p.is_file() and p.suffix in keep and "eval" not in p.parts}


def test_study_plan_has_800_100_100_per_speed_with_scenes_in_one_split():
    tasks = make_plan(DatasetConfig())
    samples = [s for t in tasks for s in t.samples]
    assert len(samples) == 2000
    for speed in ("normal", "fast"):
        mine = [s for s in samples if s.speed == speed]
        assert [sum(s.split == sp for s in mine) for sp in ("train", "val", "test")] == [800, 100, 100]
    split_of = {}
    for s in samples:
        assert split_of.setdefault(s.scene, s.split) == s.split
    assert len({s.key for s in samples}) == 2000
    assert make_plan(DatasetConfig()) == tasks
    assert make_plan(DatasetConfig(seed=1)) != tasks


def test_small_plan_quota_and_bad_options():
    samples = [s for t in make_plan(DatasetConfig(frames=20, scenes=10)) for s in t.samples]
    assert [sum(s.split == sp for s in samples) for sp in ("train", "val", "test")] == [16, 2, 2]
    with pytest.raises(ConfigError, match="frames"):
        DatasetConfig(frames=4)
    with pytest.raises(ConfigError, match="times"):
        DatasetConfig(times=("midnight",))
    with pytest.raises(ConfigError, match="multiple"):
        make_plan(DatasetConfig(frames=7, speeds=("normal", "fast")))


def test_label_policy():
    p = LabelPolicy(min_width_px=6, min_height_px=16, min_visible=0.3)
    assert p.classify((0, 0, 10, 40), 1.0) == "label"
    assert p.classify((0, 0, 10, 10), 1.0) == "ignore"
    assert p.classify((0, 0, 10, 40), 0.1) == "ignore"
    assert p.classify((0, 0, 10, 40), 0.0) is None
    assert p.classify(None, 1.0) is None


def test_build_writes_exact_labels_in_yolo_and_coco(tmp_path):
    result = build_dataset(SMALL, tmp_path / "ds")
    root = result.out_dir
    assert result.pairs == result.rendered == 6
    card = json.loads((root / "dataset.json").read_text())
    assert sorted(card["subsets"]) == ["fast_gs", "fast_rs", "normal_gs", "normal_rs"]
    rec = json.loads(next((root / "records" / "fast").glob("*.json")).read_text())
    with open_camera(rec["uri"]) as src:
        gs, rs = src.read_pair()
    for shutter, frame, attr in (("gs", gs, "box_gs"), ("rs", rs, "box_rs")):
        img = rec["images"][shutter]
        assert (root / img["file"]).is_file()
        truth = {o.id: getattr(o, attr) for o in frame.objects}
        for obj in img["objects"]:
            assert obj["box"] == pytest.approx(truth[obj["id"]], abs=1e-3)
        label = root / (img["file"].replace("/images/", "/labels/").rsplit(".", 1)[0] + ".txt")
        lines = label.read_text().splitlines()
        kept = [o for o in img["objects"] if not o["ignore"]]
        assert len(lines) == len(kept)
        for line, o in zip(lines, kept, strict=True):
            c, cx, cy, w, h = map(float, line.split())
            x0, y0, x1, y1 = o["box"]
            assert (c, cx * 192, cy * 108, w * 192, h * 108) == pytest.approx(
                (0, (x0 + x1) / 2, (y0 + y1) / 2, x1 - x0, y1 - y0), abs=1e-3)
    rs_boxes = [o["box"] for o in rec["images"]["rs"]["objects"]]
    gs_boxes = [o["box"] for o in rec["images"]["gs"]["objects"]]
    assert rs_boxes != gs_boxes  # fast walkers: the RS labels are not the GS ones
    coco = json.loads((root / "fast_rs" / "annotations" / f"{rec['split']}.json").read_text())
    assert any(i["file_name"] == f"images/{rec['split']}/{rec['name']}.png" for i in coco["images"])
    assert (root / "README.md").read_text().count("| fast_rs |") == 3


def test_same_labels_whatever_the_worker_count(tmp_path):
    a = build_dataset(SMALL, tmp_path / "a", workers=1).out_dir
    b = build_dataset(SMALL, tmp_path / "b", workers=2).out_dir
    ta, tb = _tree(a), _tree(b)
    assert ta.keys() == tb.keys() and len(ta) > 20
    assert ta == tb
    # the card's one digest of every file: what a study's report records and `rollcam study --adopt` checks
    card = json.loads((a / "dataset.json").read_text())
    assert card["content_sha256"] == content_digest(read_records(b))
    rec = next(iter(read_records(b).values()))
    rec["files"][next(iter(rec["files"]))]["sha256"] = "0" * 64
    assert content_digest({("x", "y"): rec}) != content_digest({("x", "y"): next(iter(read_records(b).values()))})


def test_interrupted_build_resumes_to_the_same_dataset(tmp_path):
    ref = _tree(build_dataset(SMALL, tmp_path / "ref").out_dir)
    out = tmp_path / "ds"
    seen = []

    def stop_after_two(result):
        seen.append(result.key)
        if len(seen) == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        build_dataset(SMALL, out, on_commit=stop_after_two)
    assert len(list((out / "records").rglob("*.json"))) == 2
    assert not (out / DRIVER_LOCK).exists()  # issue 37: main left an empty lock file behind
    assert not list(out.rglob("*.part"))
    # A sample killed half-way: a stray temporary file and a truncated image of an uncommitted sample.
    junk = out / "normal_gs" / "images" / "test" / "half.png.part"
    junk.parent.mkdir(parents=True, exist_ok=True)
    junk.write_bytes(b"x")
    result = build_dataset(SMALL, out)
    assert (result.resumed, result.rendered) == (2, 4)
    assert not junk.exists() and not (out / DRIVER_LOCK).exists()
    assert _tree(out) == ref
    with pytest.raises(ConfigError, match="other options"):
        build_dataset(DatasetConfig(size=(192, 108), scenes=3, frames=6, seed=8), out)


def test_dask_local_cluster_gives_the_same_dataset(tmp_path):
    distributed = pytest.importorskip("distributed")
    ref = _tree(build_dataset(SMALL, tmp_path / "ref").out_dir)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  silence_logs=40) as cluster:
        addr = cluster.scheduler_address.replace("tcp://", "")
        result = build_dataset(SMALL, tmp_path / "dask", executor=f"dask://{addr}")
        assert (result.executor, result.workers) == ("dask", 2)
        shared = build_dataset(SMALL, tmp_path / "dask_shared", executor=f"dask://{addr}", worker_writes=True)
    assert _tree(result.out_dir) == ref
    assert _tree(shared.out_dir) == ref


def test_cli_dataset_then_eval_with_ground_truth_detections(tmp_path, capsys):
    out = tmp_path / "ds"
    assert main(["dataset", "--out", str(out), "--frames", "6", "--scenes", "3", "--size", "192x108",
                 "--pedestrians", "12", "--seed", "7", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["pairs"] == 6
    lines = []
    for rec_path in sorted((out / "records").rglob("*.json")):
        rec = json.loads(rec_path.read_text())
        for img in rec["images"].values():
            dets = [{"box": o["box"], "score": 0.9, "cls": 0} for o in img["objects"] if not o["ignore"]]
            lines.append(json.dumps({"image": img["file"], "detections": dets}))
    det_file = tmp_path / "detections.jsonl"
    det_file.write_text("\n".join(lines) + "\n")
    assert main(["eval", str(out), "--detections", str(det_file), "--split", "train", "--json",
                 "--out", str(tmp_path / "ev")]) == 0
    doc = json.loads(capsys.readouterr().out)
    for speed in ("normal", "fast"):
        for shutter in ("gs", "rs"):
            m = doc["results"][speed][shutter]
            assert (m["P"], m["R"], m["mAP50"], m["mAP50_95"]) == pytest.approx((1, 1, 1, 1), abs=1e-6)
        assert doc["results"][speed]["gs_to_rs"]["mAP50_95"] == pytest.approx(0, abs=1e-6)
    assert Path(doc["files"]["chart"]).stat().st_size > 1000
    # One subset goes to its own files: the four-subset results stay as they were.
    full = Path(doc["files"]["json"]).read_bytes()
    assert main(["eval", str(out), "--detections", str(det_file), "--split", "train", "--subset", "fast_rs",
                 "--json", "--out", str(tmp_path / "ev")]) == 0
    one = json.loads(capsys.readouterr().out)
    assert list(one["results"]) == ["fast"] and set(one["results"]["fast"]) == {"rs"}
    assert Path(one["files"]["json"]).name == "detections_train_fast_rs.json"
    assert Path(doc["files"]["json"]).read_bytes() == full
    assert json.loads(Path(one["files"]["json"]).read_text())["results"] == one["results"]
    # The detector path runs end to end too (HOG finds little at 192x108; the point is the plumbing).
    assert main(["eval", str(out), "--detector", "hog", "--split", "val", "--out", str(tmp_path / "ev")]) == 0
    assert "Normal_GS" in capsys.readouterr().out
    # One subset as a plain COCO file (images found beside annotations/) and as an Ultralytics data.yaml.
    assert main(["eval", str(out / "fast_rs" / "annotations" / "val.json"), "--detector", "hog",
                 "--out", str(tmp_path / "ev")]) == 0
    assert main(["eval", str(out / "fast_rs" / "data.yaml"), "--detector", "hog", "--split", "val",
                 "--out", str(tmp_path / "ev")]) == 0
    assert main(["dataset", "--out", str(tmp_path / "bad"), "--frames", "6", "--times", "midnight"]) == 2
