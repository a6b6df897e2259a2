"""Evaluation metrics: faster-coco-eval equals pycocotools; P and R as Ultralytics reports them; loaders."""

from __future__ import annotations

import json

import numpy as np
import pytest
from rollcam.common.errors import RollcamError
from rollcam.host.evaluation.loaders import load_detections, load_sets
from rollcam.host.evaluation.metrics import Dets, Truth, box_iou, coco_map, evaluate, precision_recall

pytest.importorskip("faster_coco_eval")


def random_case(seed: int, n_images: int = 60, n_classes: int = 2):
    rng = np.random.default_rng(seed)
    truths, dets = [], []
    for _ in range(n_images):
        n = int(rng.integers(0, 7))
        xy = rng.uniform(0, 600, (n, 2))
        boxes = np.c_[xy, xy + rng.uniform(8, 200, (n, 2))]
        truths.append(Truth.of(boxes, rng.integers(0, n_classes, n), rng.random(n) < 0.15, 800, 600))
        m = int(rng.integers(0, 9))
        base = boxes[rng.integers(0, n, m)] if n else rng.uniform(0, 500, (m, 4))
        d = base + rng.normal(0, rng.uniform(1, 30), (m, 4))
        d[:, 2:] = np.maximum(d[:, 2:], d[:, :2] + 1)
        dets.append(Dets.of(d, rng.random(m), rng.integers(0, n_classes, m)))
    return truths, dets


@pytest.mark.parametrize("seed", range(6))
def test_faster_coco_eval_equals_pycocotools_on_random_inputs(seed):
    pytest.importorskip("pycocotools")
    truths, dets = random_case(seed)
    fast = coco_map(truths, dets, "faster")
    ref = coco_map(truths, dets, "pycocotools")
    assert fast["mAP50"] == pytest.approx(ref["mAP50"], abs=1e-6)
    assert fast["mAP50_95"] == pytest.approx(ref["mAP50_95"], abs=1e-6)
    assert 0 < fast["mAP50_95"] < fast["mAP50"] < 1


def test_perfect_and_empty_detections():
    truths, _ = random_case(3)
    perfect = [Dets.of(t.boxes[~t.ignore], np.full((~t.ignore).sum(), 0.9), t.classes[~t.ignore]) for t in truths]
    m = evaluate(truths, perfect)
    assert (m["P"], m["R"], m["mAP50"], m["mAP50_95"]) == pytest.approx((1, 1, 1, 1), abs=1e-6)
    none = [Dets.of(np.zeros((0, 4)), [], []) for _ in truths]
    m = evaluate(truths, none)
    assert (m["P"], m["R"], m["mAP50"], m["mAP50_95"]) == (0, 0, 0, 0)


def test_precision_recall_at_best_f1():
    # Ultralytics reads P and R on a 1,000-step confidence grid, interpolating linearly between detections'
    # confidences, at the argmax of mean F1 smoothed over a 0.1-wide window.
    t = Truth.of([[0, 0, 10, 30], [50, 0, 60, 30]], [0, 0])
    d = Dets.of([[0, 0, 10, 30], [50, 1, 60, 30], [300, 0, 310, 30]], [0.95, 0.9, 0.1], [0, 0, 0])
    pr = precision_recall([t], [d])
    assert pr["R"] == pytest.approx(1.0)
    assert 0.95 < pr["P"] < 1.0 and 0.7 < pr["conf"] < 0.9
    # One true detection out of two people, one false one below it: R 0.5 wherever the grid lands.
    d = Dets.of([[0, 0, 10, 30], [200, 200, 210, 230]], [0.9, 0.5], [0, 0])
    pr = precision_recall([t], [d])
    assert pr["R"] == pytest.approx(0.5) and 0.5 < pr["P"] <= 1.0


def test_detections_on_ignore_regions_are_neither_true_nor_false():
    t = Truth.of([[0, 0, 10, 30], [100, 0, 104, 8]], [0, 0], [False, True])
    d = Dets.of([[0, 0, 10, 30], [100, 0, 104, 8]], [0.9, 0.95], [0, 0])
    m = evaluate([t], [d])
    assert (m["P"], m["R"], m["mAP50"]) == pytest.approx((1, 1, 1), abs=1e-6)
    assert m["boxes"] == 1


def test_box_iou():
    a = np.array([[0, 0, 10, 10.0]])
    b = np.array([[0, 0, 10, 10.0], [5, 0, 15, 10], [20, 20, 30, 30]])
    assert box_iou(a, b)[0] == pytest.approx([1, 1 / 3, 0])


def test_coco_file_and_results_json(tmp_path):
    coco = {"images": [{"id": 7, "file_name": "a.png", "width": 100, "height": 80}],
            "annotations": [{"id": 1, "image_id": 7, "category_id": 1, "bbox": [10, 10, 20, 40], "area": 800,
                             "iscrowd": 0}],
            "categories": [{"id": 1, "name": "person"}]}
    (tmp_path / "gt.json").write_text(json.dumps(coco))
    (tmp_path / "res.json").write_text(json.dumps([{"image_id": 7, "category_id": 1, "bbox": [10, 10, 20, 40],
                                                     "score": 0.7}]))
    sets = load_sets(tmp_path / "gt.json", "test")
    dets = load_detections(tmp_path / "res.json", sets)
    assert dets[0][0].boxes.tolist() == [[10, 10, 30, 50]]
    assert evaluate([e.truth for e in sets[0].images], dets[0])["mAP50_95"] == pytest.approx(1.0)


def test_yolo_dataset_loader(tmp_path):
    import cv2

    (tmp_path / "images" / "val").mkdir(parents=True)
    (tmp_path / "labels" / "val").mkdir(parents=True)
    cv2.imwrite(str(tmp_path / "images" / "val" / "x.png"), np.zeros((50, 100, 3), np.uint8))
    (tmp_path / "labels" / "val" / "x.txt").write_text("0 0.5 0.5 0.2 0.4\n")
    (tmp_path / "data.yaml").write_text("val: images/val\nnames:\n  0: person\n")
    (s,) = load_sets(tmp_path, "val")
    assert s.images[0].truth.boxes[0].tolist() == pytest.approx([40, 15, 60, 35])
    (tmp_path / "d.jsonl").write_text(json.dumps({"image": "x.png", "detections": [
        {"box": [40, 15, 60, 35], "score": 0.5, "class": "person"}]}) + "\n")
    dets = load_detections(tmp_path / "d.jsonl", [s])
    assert evaluate([s.images[0].truth], dets[0])["mAP50"] == pytest.approx(1.0)


_GOOD = {"images": [{"id": 7, "file_name": "a.png", "width": 100, "height": 80}],
         "annotations": [{"id": 1, "image_id": 7, "category_id": 1, "bbox": [10, 10, 20, 40]}],
         "categories": [{"id": 1, "name": "person"}]}


@pytest.mark.parametrize(("change", "message"), [
    ({"annotations": [{"id": 1, "image_id": 7, "category_id": 1, "bbox": [float("nan"), 1, 5, 5]}]},
     r"gt\.json'? annotation 0 \(id 1\) bbox: box \[x, y, w, h\] must be finite numbers"),
    ({"annotations": [{"id": 1, "image_id": 7, "category_id": 1, "bbox": [1e308, 0, 1e308, 5]}]},
     r"annotation 0 \(id 1\) bbox: box .* reaches more than 100 frames beyond the 100x80 image"),
    ({"annotations": [{"id": 1, "image_id": 7, "category_id": 1, "bbox": [0, 0, -5, 5]}]},
     r"annotation 0 \(id 1\) bbox: box width and height must be >= 0"),
    ({"annotations": [{"id": 1, "image_id": 8, "category_id": 1, "bbox": [0, 0, 5, 5]}]},
     r"annotation 0 \(id 1\): image_id 8 names no image"),
    ({"annotations": [{"id": 1, "image_id": 7, "category_id": 1}]}, r"annotation 0 \(id 1\): bbox must be"),
    ({"images": [{"id": 7}]}, r"gt\.json'? image 0: needs an 'id' and a 'file_name'"),
    ({"categories": [{"name": "person"}]}, r"gt\.json'? category 0: needs an integer 'id'"),
    ({"annotations": {}}, r"gt\.json'?: not a COCO file"),
])
def test_bad_coco_eval_files_name_the_file_and_annotation(tmp_path, change, message):
    """Issue 37 item 4: main accepted NaN and far-off boxes silently and ended in a KeyError traceback on the rest."""
    (tmp_path / "gt.json").write_text(json.dumps({**_GOOD, **change}))
    with pytest.raises(RollcamError, match=message):
        load_sets(tmp_path / "gt.json", "test")


@pytest.mark.parametrize(("line", "message"), [
    ("nan 0.5 0.5 0.2 0.4", r"x\.txt'? line 1: class must be an integer >= 0"),
    ("0 inf 0.5 0.2 0.4", r"x\.txt'? line 1: box \[x, y, w, h\] must be finite numbers"),
    ("0 0.5 0.5 -0.2 0.4", r"x\.txt'? line 1: box width and height must be >= 0"),
    ("0 0.5 0.5", r"x\.txt'? line 1: need 'class cx cy w h'"),
    ("0 a b c d", r"x\.txt'? line 1: not numbers"),
])
def test_bad_yolo_eval_labels_name_the_file_and_line(tmp_path, line, message):
    import cv2

    (tmp_path / "images" / "val").mkdir(parents=True)
    (tmp_path / "labels" / "val").mkdir(parents=True)
    cv2.imwrite(str(tmp_path / "images" / "val" / "x.png"), np.zeros((50, 100, 3), np.uint8))
    (tmp_path / "labels" / "val" / "x.txt").write_text(line + "\n")
    (tmp_path / "data.yaml").write_text("val: images/val\nnames:\n  0: person\n")
    with pytest.raises(RollcamError, match=message):
        load_sets(tmp_path, "val")


@pytest.mark.parametrize(("suffix", "content", "message"), [
    (".json", [{"image_id": 7, "category_id": 1, "bbox": [float("nan"), 0, 1, 1], "score": 0.5}],
     r"res\.json'? result 0 bbox: box \[x, y, w, h\] must be finite numbers"),
    (".json", [{"image_id": 7, "bbox": [0, 0, 1, 1], "score": 0.5}], r"res\.json'? result 0: expected"),
    (".jsonl", {"image": "a.png", "detections": [{"box": [0, 0, float("inf"), 1], "score": 0.5, "cls": 0}]},
     r"res\.jsonl:1: a detection is .* of finite numbers"),
    (".jsonl", {"image": "a.png", "detections": [{"score": 0.5}]}, r"res\.jsonl:1: a detection is"),
])
def test_bad_detection_files_name_the_file_and_entry(tmp_path, suffix, content, message):
    (tmp_path / "gt.json").write_text(json.dumps(_GOOD))
    sets = load_sets(tmp_path / "gt.json", "test")
    (tmp_path / f"res{suffix}").write_text(json.dumps(content) + "\n")
    with pytest.raises(RollcamError, match=message):
        load_detections(tmp_path / f"res{suffix}", sets)
