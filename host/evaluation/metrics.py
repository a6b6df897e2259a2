"""Detection metrics as the study reports them: P and R at the confidence of best mean F1 (Ultralytics'
``ap_per_class``), and COCO mAP@0.5 and mAP@0.5:0.95 from a maintained COCO evaluator (faster-coco-eval;
pycocotools gives the same numbers and serves as the cross-check in the tests).

Inputs are per-image arrays: ``Truth`` (boxes x0, y0, x1, y1 in pixels, 0-based class ids, an ignore flag for
regions a detector is neither rewarded nor punished for) and ``Dets`` (boxes, scores, classes).
"""

from __future__ import annotations

import contextlib
import io
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from rollcam.common.errors import require
from rollcam.host.detectors.ops import ioa_matrix, iou_matrix

EPS = 1e-16


@dataclass(frozen=True)
class Truth:
    """Ground truth of one image; ``ignore[i]`` marks an ignore region (COCO ``iscrowd=1``)."""

    boxes: np.ndarray
    classes: np.ndarray
    ignore: np.ndarray
    width: int = 0
    height: int = 0

    @classmethod
    def of(cls, boxes: Any, classes: Any, ignore: Any = None, width: int = 0, height: int = 0) -> Truth:
        """Normalise array shapes and dtypes."""
        b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
        c = np.asarray(classes, dtype=np.int64).reshape(-1)
        ig = np.zeros(len(b), bool) if ignore is None else np.asarray(ignore, dtype=bool).reshape(-1)
        return cls(b, c, ig, width, height)


@dataclass(frozen=True)
class Dets:
    """Detections of one image."""

    boxes: np.ndarray
    scores: np.ndarray
    classes: np.ndarray

    @classmethod
    def of(cls, boxes: Any, scores: Any, classes: Any) -> Dets:
        """Normalise array shapes and dtypes."""
        return cls(np.asarray(boxes, dtype=np.float64).reshape(-1, 4), np.asarray(scores, dtype=np.float64).reshape(-1),
                   np.asarray(classes, dtype=np.int64).reshape(-1))


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU of every box in ``a`` (N, 4) with every box in ``b`` (M, 4), xyxy: (N, M), in Ultralytics' form
    (intersection / (union + EPS)), as its P and R are computed."""
    return iou_matrix(a, b, eps=EPS)


def match_image(truth: Truth, dets: Dets, iou_thr: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Ultralytics' ``match_predictions`` at one IoU threshold: greedy by IoU, one truth per detection.

    Returns (tp flags per detection, keep mask): detections that match no labelled box but lie on an ignore
    region (intersection over their area >= ``iou_thr``) are dropped, as the COCO evaluator drops them.
    """
    n = len(dets.scores)
    tp = np.zeros(n, bool)
    keep = np.ones(n, bool)
    lab = ~truth.ignore
    tb, tc = truth.boxes[lab], truth.classes[lab]
    if n and len(tb):
        iou = box_iou(tb, dets.boxes) * (tc[:, None] == dets.classes[None, :])
        li, di = np.nonzero(iou >= iou_thr)
        if len(li):
            m = np.stack([li, di], 1)
            if len(m) > 1:
                m = m[iou[m[:, 0], m[:, 1]].argsort()[::-1]]
                m = m[np.unique(m[:, 1], return_index=True)[1]]
                m = m[np.unique(m[:, 0], return_index=True)[1]]
            tp[m[:, 1]] = True
    if n and truth.ignore.any():
        rb, rc = truth.boxes[truth.ignore], truth.classes[truth.ignore]
        on_region = ((ioa_matrix(dets.boxes, rb, eps=EPS) >= iou_thr) & (dets.classes[:, None] == rc[None, :])).any(1)
        keep = tp | ~on_region
    return tp, keep


def _smooth(y: np.ndarray, f: float = 0.05) -> np.ndarray:
    nf = round(len(y) * f * 2) // 2 + 1
    p = np.ones(nf // 2)
    yp = np.concatenate((p * y[0], y, p * y[-1]), 0)
    return np.convolve(yp, np.ones(nf) / nf, mode="valid")


def to_unit_scores(scores: np.ndarray) -> np.ndarray:
    """Scores as confidences in [0, 1]: unchanged when already there, else a logistic (order-preserving) map,
    since P and R are read on a 0..1 confidence grid (SVM margins such as HOG's are not probabilities)."""
    if scores.size == 0 or (scores.min() >= 0.0 and scores.max() <= 1.0):
        return scores
    return 1.0 / (1.0 + np.exp(-scores))


def precision_recall(truths: Sequence[Truth], dets: Sequence[Dets]) -> dict[str, float]:
    """P and R at the confidence of best mean F1 over classes, as Ultralytics' ``ap_per_class`` reports them."""
    tps, confs, pcls, tcls = [], [], [], []
    for t, d in zip(truths, dets, strict=True):
        tp, keep = match_image(t, d)
        tps.append(tp[keep])
        confs.append(d.scores[keep])
        pcls.append(d.classes[keep])
        tcls.append(t.classes[~t.ignore])
    tp = np.concatenate(tps) if tps else np.zeros(0, bool)
    conf = to_unit_scores(np.concatenate(confs)) if confs else np.zeros(0)
    pred_cls = np.concatenate(pcls) if pcls else np.zeros(0, np.int64)
    target_cls = np.concatenate(tcls) if tcls else np.zeros(0, np.int64)
    order = np.argsort(-conf, kind="stable")
    tp, conf, pred_cls = tp[order].astype(np.float64), conf[order], pred_cls[order]
    classes, n_targets = np.unique(target_cls, return_counts=True)
    x = np.linspace(0, 1, 1000)
    p_curve, r_curve = np.zeros((len(classes), 1000)), np.zeros((len(classes), 1000))
    for ci, c in enumerate(classes):
        sel = pred_cls == c
        if not sel.any():
            continue
        tpc = tp[sel].cumsum()
        fpc = (1 - tp[sel]).cumsum()
        r_curve[ci] = np.interp(-x, -conf[sel], tpc / (n_targets[ci] + EPS), left=0)
        p_curve[ci] = np.interp(-x, -conf[sel], tpc / (tpc + fpc), left=1)
    if not len(classes):
        return {"P": 0.0, "R": 0.0, "conf": 0.0, "F1": 0.0}
    f1 = 2 * p_curve * r_curve / (p_curve + r_curve + EPS)
    i = int(_smooth(f1.mean(0), 0.1).argmax())
    return {"P": float(p_curve[:, i].mean()), "R": float(r_curve[:, i].mean()), "conf": float(x[i]),
            "F1": float(f1[:, i].mean())}


def coco_documents(truths: Sequence[Truth], dets: Sequence[Dets]) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Ground truth as a COCO dataset dict and detections as a COCO results list (category id = class + 1)."""
    images, anns, results = [], [], []
    cats: set[int] = set()
    for i, (t, d) in enumerate(zip(truths, dets, strict=True), start=1):
        images.append({"id": i, "width": int(t.width), "height": int(t.height)})
        for b, c, ig in zip(t.boxes.tolist(), t.classes.tolist(), t.ignore.tolist(), strict=True):
            w, h = b[2] - b[0], b[3] - b[1]
            anns.append({"id": len(anns) + 1, "image_id": i, "category_id": c + 1, "bbox": [b[0], b[1], w, h],
                         "area": w * h, "iscrowd": int(ig)})
            cats.add(c)
        for b, s, c in zip(d.boxes.tolist(), d.scores.tolist(), d.classes.tolist(), strict=True):
            results.append({"image_id": i, "category_id": c + 1, "bbox": [b[0], b[1], b[2] - b[0], b[3] - b[1]],
                            "score": s})
            cats.add(c)
    gt = {"images": images, "annotations": anns, "categories": [{"id": c + 1, "name": str(c)} for c in sorted(cats)]}
    return gt, results


def coco_map(truths: Sequence[Truth], dets: Sequence[Dets], backend: str = "faster") -> dict[str, float]:
    """COCO bbox mAP@0.5 and mAP@0.5:0.95 (``backend``: ``faster`` = faster-coco-eval, or ``pycocotools``)."""
    gt, results = coco_documents(truths, dets)
    if not any(a["iscrowd"] == 0 for a in gt["annotations"]):
        return {"mAP50": 0.0, "mAP50_95": 0.0}  # nothing to find: COCO reports -1, a table wants 0
    if not results:
        return {"mAP50": 0.0, "mAP50_95": 0.0}
    if backend == "faster":
        require("faster_coco_eval", "faster-coco-eval", "eval", "rollcam eval")
        from faster_coco_eval import COCO, COCOeval_faster
        quiet = lambda *_a, **_k: None  # noqa: E731
        coco_gt = COCO(gt, print_function=quiet)
        coco_dt = coco_gt.loadRes(results)
        ev = COCOeval_faster(coco_gt, coco_dt, iouType="bbox", print_function=quiet)
    elif backend == "pycocotools":
        from pycocotools.coco import COCO as PyCOCO
        from pycocotools.cocoeval import COCOeval

        with contextlib.redirect_stdout(io.StringIO()):
            coco_gt = PyCOCO()
            coco_gt.dataset = gt
            coco_gt.createIndex()
            coco_dt = coco_gt.loadRes(results)
            ev = COCOeval(coco_gt, coco_dt, iouType="bbox")
    else:
        raise ValueError(f"backend {backend!r} is not 'faster' or 'pycocotools'")
    with contextlib.redirect_stdout(io.StringIO()):
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    stats = ev.stats
    return {"mAP50": max(float(stats[1]), 0.0), "mAP50_95": max(float(stats[0]), 0.0)}


def evaluate(truths: Sequence[Truth], dets: Sequence[Dets], backend: str = "faster") -> dict[str, Any]:
    """P, R, mAP50 and mAP50_95 of detections against truths, plus counts."""
    if len(truths) != len(dets):
        raise ValueError(f"{len(truths)} truths but {len(dets)} detection lists")
    out: dict[str, Any] = {}
    pr = precision_recall(truths, dets)
    out.update(P=pr["P"], R=pr["R"])
    out.update(coco_map(truths, dets, backend))
    out.update(conf=pr["conf"], images=len(truths), boxes=int(sum(int((~t.ignore).sum()) for t in truths)),
               detections=int(sum(len(d.scores) for d in dets)))
    return out
