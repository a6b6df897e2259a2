"""Evaluation metrics: faster-coco-eval equals pycocotools; P and R as Ultralytics reports them; loaders."""

from __future__ import annotations

import json

import numpy as np
import pytest
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
