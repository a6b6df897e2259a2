"""Running precision and recall of detections against a synthetic frame's ground truth (GS and RS boxes).

Per frame and per truth kind (``rs``: the union of an object's rows at their own read times; ``gs``: the
object at the frame's reference instant), person detections are matched greedily, highest score first,
one-to-one to the kept person boxes at IoU >= ``iou``. Kept: boxes at least ``min_height_px`` tall with at
least ``min_visible`` of their pixels unoccluded. Detections that match only boxes left out (too small,
hidden) are neither credited nor charged, as with the "ignore" regions of pedestrian benchmarks.
These are running counts for a live display; COCO-style mAP belongs to ``rollcam eval``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from rollcam.sim.frame import Frame

from ..detectors import PERSON, Detections
from ..detectors.ops import iou_matrix

KINDS = {"rs": "box_rs", "gs": "box_gs"}
"""Truth kind -> ObjectTruth attribute holding its box."""


@dataclass
class Counts:
    """True positives, false positives, missed and ignored detections of one truth kind."""

    tp: int = 0
    fp: int = 0
    fn: int = 0
    ignored: int = 0

    def add(self, other: Counts) -> None:
        self.tp, self.fp = self.tp + other.tp, self.fp + other.fp
        self.fn, self.ignored = self.fn + other.fn, self.ignored + other.ignored

    @property
    def precision(self) -> float | None:
        """TP / (TP + FP), or None before any counted detection."""
        return self.tp / (self.tp + self.fp) if self.tp + self.fp else None

    @property
    def recall(self) -> float | None:
        """TP / (TP + FN), or None before any kept object."""
        return self.tp / (self.tp + self.fn) if self.tp + self.fn else None

    def to_json(self) -> dict[str, Any]:
        def r(v: float | None) -> float | None:
            return None if v is None else round(v, 4)

        return {"tp": self.tp, "fp": self.fp, "fn": self.fn, "ignored": self.ignored,
                "precision": r(self.precision), "recall": r(self.recall)}


def match(boxes: np.ndarray, kept: np.ndarray, ignored: np.ndarray, iou: float) -> Counts:
    """Greedy one-to-one matching of score-ordered ``boxes`` to ``kept``; ``ignored`` absorbs the rest."""
    c = Counts()
    free = np.ones(len(kept), bool)
    ious = iou_matrix(boxes, kept) if len(kept) else np.zeros((len(boxes), 0))
    ious_ign = iou_matrix(boxes, ignored) if len(ignored) else np.zeros((len(boxes), 0))
    for i in range(len(boxes)):
        cand = np.where(free, ious[i], -1.0) if len(kept) else np.zeros(0)
        if len(cand) and cand.max() >= iou:
            free[int(cand.argmax())] = False
            c.tp += 1
        elif len(ignored) and ious_ign[i].max() >= iou:
            c.ignored += 1
        else:
            c.fp += 1
    c.fn = int(free.sum())
    return c


@dataclass
class RunningPR:
    """Accumulates Counts per truth kind over a stream of (frame, detections)."""

    iou: float = 0.5
    min_height_px: float = 0.0
    min_visible: float = 0.25
    totals: dict[str, Counts] = field(default_factory=lambda: {k: Counts() for k in KINDS})
    frames: int = 0

    def update(self, frame: Frame, dets: Detections) -> dict[str, Counts] | None:
        """Match one frame (None when it has no ground truth) and add it to the totals."""
        if frame.objects is None:
            return None
        persons = dets.classes == PERSON
        boxes = dets.boxes[persons][np.argsort(-dets.scores[persons], kind="stable")]
        out = {}
        for kind, attr in KINDS.items():
            kept, ignored = [], []
            for o in frame.objects:
                box = getattr(o, attr)
                if box is None or o.cls != "person":
                    continue
                ok = box[3] - box[1] >= self.min_height_px and o.visible >= self.min_visible
                (kept if ok else ignored).append(box)
            c = match(boxes, np.asarray(kept, np.float64).reshape(-1, 4),
                      np.asarray(ignored, np.float64).reshape(-1, 4), self.iou)
            self.totals[kind].add(c)
            out[kind] = c
        self.frames += 1
        return out

    def summary(self) -> str:
        """``P/R rs 0.80/0.45  gs 0.75/0.42`` for the status line."""
        def f(v: float | None) -> str:
            return "  - " if v is None else f"{v:.2f}"
        return "  ".join(f"{k} P {f(c.precision)} R {f(c.recall)}" for k, c in self.totals.items())

    def to_json(self) -> dict[str, Any]:
        return {"iou": self.iou, "min_height_px": self.min_height_px, "min_visible": self.min_visible,
                "frames": self.frames, **{k: c.to_json() for k, c in self.totals.items()}}
