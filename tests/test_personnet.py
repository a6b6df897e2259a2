"""The packaged ``personnet`` detector: it loads, its card matches its file, and it finds rendered walkers."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
from rollcam.common.errors import ConfigError
from rollcam.host.detectors import DETECTORS, load_detector
from rollcam.host.detectors.ops import iou_matrix

pytest.importorskip("onnxruntime")


def test_card_describes_the_packaged_file():
    from rollcam.host.detectors import personnet

    card = personnet.card()
    data = personnet.model_path().read_bytes()
    assert card["licence"] == "MIT" and card["figures"]["sha256"] == hashlib.sha256(data).hexdigest()
    assert len(data) <= 15e6 and 0 < personnet.default_conf() < 1
    assert card["training"]["config"]["imgsz"] == "640x360"


def test_personnet_finds_walkers_in_a_rendered_street_frame():
    from rollcam.host import open_camera
    from rollcam.host.detectors import personnet

    assert "personnet" in DETECTORS
    det = load_detector("personnet")
    try:
        assert det.name == "personnet" and det.class_names == {0: "person"} and (det.width, det.height) == (640, 360)
        assert det.conf == pytest.approx(personnet.default_conf())
        assert len(det.detect(np.full((360, 640, 3), 128, np.uint8))) == 0  # a flat grey frame holds nobody
        # A scene seed no training scene used (the dataset's seeds are drawn below 2**31 from its own seed).
        with open_camera("emu:letsroll?seed=7&pedestrians=20&camera=1&speed=fast&shutter=rolling&frames=1") as cam:
            frame = cam.read()
        d = det.detect(frame.data)
    finally:
        det.close()
    # Walkers a labeller would box: tall enough at 1080p and mostly in view (the dataset's policy, more strictly).
    truth = np.array([o.box_rs for o in frame.objects if o.box_rs is not None and o.visible >= 0.7
                      and o.box_rs[3] - o.box_rs[1] >= 48], np.float32).reshape(-1, 4)
    assert len(truth) >= 3 and len(d) >= 1 and (d.classes == 0).all()
    found = (iou_matrix(truth, d.boxes).max(axis=1) >= 0.5).mean()
    assert found >= 0.6, f"found {found:.0%} of {len(truth)} walkers"


def test_personnet_reports_nobody_in_featureless_frames():
    # A camera's black start-up frames, a covered lens, a blown-out frame: flat levels from black to white, clean
    # and with 2 DN of noise (the bench's figure). The stage shipped before background images boxed up to 12
    # frame-high people in a clean dark grey.
    from rollcam.benchmarks.personnet import flat_frames
    from rollcam.host.detectors import personnet

    got = flat_frames(personnet.model_path(), personnet.default_conf(), personnet.default_iou())
    assert got["frames"] == 34 and got["frames_with_fp"] == 0, got
    assert got["max_score"] < personnet.default_conf() - 0.1  # not a near miss


def test_personnet_options_are_those_of_a_packaged_model():
    with pytest.raises(ConfigError, match="fixed by the personnet model"):
        load_detector("personnet?letterbox=0")
    with pytest.raises(ConfigError, match="personnet takes no target"):
        load_detector("personnet:other.onnx")
    det = load_detector("personnet?conf=0.6&threads=1")
    assert det.conf == pytest.approx(0.6)
    det.close()


def test_bench_targets_apply_only_to_what_was_measured():
    from rollcam.benchmarks.personnet import format_report, targets

    doc = {"model": "m.onnx", "file_mb": 0.08, "ms_model": 3.0, "ms_detect": 20.0, "ms_model_min": 2.0,
           "ms_detect_min": 9.0, "empty": {"frames": 15, "conf": 0.3, "fp_per_frame": 0.0, "frames_with_fp": 0,
                                           "max_fp": 0}}
    t = targets(doc)
    assert t["file_mb"]["pass"] is True and t["ms_detect"]["pass"] is False
    assert t["mAP50"]["pass"] is None and t["mAP50_95"]["value"] is None
    doc["pooled"] = {"mAP50": 0.95, "mAP50_95": 0.55}
    t = targets(doc)
    assert t["mAP50"]["pass"] is True and t["mAP50_95"]["pass"] is False
    doc["targets"] = t
    text = format_report(doc)
    assert "target ms_detect: 20.0 <= 15.0: FAIL" in text and "target mAP50: 0.95 >= 0.9: PASS" in text
    assert "featureless" not in text  # a document from before the figure
    doc["flat"] = {"frames": 34, "conf": 0.3, "fp_per_frame": 0.5, "frames_with_fp": 4, "max_fp": 12,
                   "max_score": 0.44}
    assert "featureless frames: 0.5 false positives per frame at conf 0.3 (4 of 34 frames with any; highest " \
           "score 0.44)" in format_report(doc)


def test_bench_counts_what_a_detector_reports_on_featureless_frames():
    from rollcam.benchmarks.personnet import FLAT_LEVELS, flat_frames
    from rollcam.host.detectors import personnet

    doc = flat_frames(personnet.model_path(), 0.0, personnet.default_iou())
    assert doc["frames"] == 2 * len(FLAT_LEVELS) and FLAT_LEVELS[0] == 0 and FLAT_LEVELS[-1] == 255
    # at conf 0 every detection counts, so the count and the top score agree on whether there was one
    assert (doc["frames_with_fp"] > 0) == (doc["max_score"] > 0)
    strict = flat_frames(personnet.model_path(), 1.01, personnet.default_iou())
    assert strict["frames_with_fp"] == 0 and strict["max_score"] == doc["max_score"]


def test_personnet_nms_iou_defaults_to_the_cards_and_an_option_overrides_it():
    from rollcam.host.detectors import personnet

    assert 0 < personnet.default_iou() <= 1
    det = load_detector("personnet")
    other = load_detector("personnet?iou=0.3")
    try:
        assert det.iou == pytest.approx(personnet.default_iou()) and other.iou == pytest.approx(0.3)
    finally:
        det.close()
        other.close()


def test_bench_picks_the_nms_iou_on_val_and_scores_test_as_the_detector_would(tmp_path):
    from pathlib import Path

    from rollcam.benchmarks.personnet import IOU_GRID, _suppress, scores
    from rollcam.host.datasets import DatasetConfig, build_dataset
    from rollcam.host.detectors import personnet
    from rollcam.host.evaluation.loaders import load_rollcam, run_detector
    from rollcam.host.evaluation.metrics import evaluate

    ds = build_dataset(DatasetConfig(size=(640, 360), scenes=10, cameras=1, times=("noon",), speeds=("fast",),
                                     frames=10, pedestrians=20, seed=9), tmp_path / "ds").out_dir
    model = personnet.model_path()
    doc = scores(model, Path(ds))
    assert doc["iou"] in IOU_GRID and set(doc["val_by_iou"]) == {str(t) for t in IOU_GRID}
    best = max(m["mAP50_95"] for m in doc["val_by_iou"].values())
    assert doc["val_by_iou"][str(doc["iou"])]["mAP50_95"] == best
    # NMS applied afterwards to detections found with NMS off = the detector run at that IoU
    test = load_rollcam(Path(ds), "test")
    off = load_detector(f"onnx:{model}?conf=0.01&iou=1")
    at = load_detector(f"onnx:{model}?conf=0.01&iou={doc['iou']}")
    try:
        found = [d for s in test for d in run_detector(off, s)]
        direct = [d for s in test for d in run_detector(at, s)]
    finally:
        off.close()
        at.close()
    later = _suppress(found, doc["iou"])
    assert sum(len(d.boxes) for d in found) >= sum(len(d.boxes) for d in later) > 0
    for a, b in zip(later, direct, strict=True):
        assert np.array_equal(a.boxes, b.boxes) and np.array_equal(a.scores, b.scores)
    pooled = evaluate([e.truth for s in test for e in s.images], direct)
    assert doc["pooled"]["mAP50_95"] == pytest.approx(pooled["mAP50_95"])
    assert doc["pooled"]["mAP50"] == pytest.approx(pooled["mAP50"])
