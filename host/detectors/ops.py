"""Image and box operations the CNN detectors share: letterboxing, resizing, NMS and tiling.

Plain numpy/OpenCV functions (NMS's greedy pass is one compiled loop), so each can be tested on its own and
reused by any model wrapper.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numba import njit
from rollcam.sim._jitcache import guard

LETTERBOX_FILL = 114
"""Grey of the letterbox bars (the Ultralytics convention the YOLO exports were trained with)."""


@dataclass(frozen=True)
class Placement:
    """How a source image was fitted into the network input: ``net = src * scale + pad`` per axis."""

    scale_x: float
    scale_y: float
    pad_x: float
    pad_y: float

    def to_source(self, boxes: np.ndarray) -> np.ndarray:
        """Network-input pixel boxes (N, 4) x0, y0, x1, y1 back to source-image pixels."""
        out = np.asarray(boxes, np.float32).copy()
        out[:, [0, 2]] = (out[:, [0, 2]] - self.pad_x) / self.scale_x
        out[:, [1, 3]] = (out[:, [1, 3]] - self.pad_y) / self.scale_y
        return out


def letterbox(image: np.ndarray, width: int, height: int, fill: int = LETTERBOX_FILL) -> tuple[np.ndarray, Placement]:
    """``image`` scaled to fit ``width`` x ``height`` keeping its aspect ratio, centred on ``fill`` bars."""
    h, w = image.shape[:2]
    scale = min(width / w, height / h)
    nw, nh = max(round(w * scale), 1), max(round(h * scale), 1)
    resized = cv2.resize(image, (nw, nh), interpolation=cv2.INTER_LINEAR) if (nw, nh) != (w, h) else image
    px, py = (width - nw) // 2, (height - nh) // 2
    out = np.full((height, width, *image.shape[2:]), fill, dtype=image.dtype)
    out[py:py + nh, px:px + nw] = resized
    return out, Placement(nw / w, nh / h, px, py)


def stretch(image: np.ndarray, width: int, height: int) -> tuple[np.ndarray, Placement]:
    """``image`` resized to exactly ``width`` x ``height`` (aspect ratio not kept; SSD-style models)."""
    h, w = image.shape[:2]
    out = cv2.resize(image, (width, height), interpolation=cv2.INTER_LINEAR) if (w, h) != (width, height) else image
    return out, Placement(width / w, height / h, 0.0, 0.0)


def _boxes(x: Any) -> np.ndarray:
    return np.asarray(x, np.float64).reshape(-1, 4)


def box_areas(boxes: Any) -> np.ndarray:
    """The area of each (x0, y0, x1, y1) box in ``boxes`` (N, 4); an inverted box has area 0."""
    b = _boxes(boxes)
    return (b[:, 2] - b[:, 0]).clip(0) * (b[:, 3] - b[:, 1]).clip(0)


def intersections(a: Any, b: Any) -> np.ndarray:
    """The area each box of ``a`` (N, 4) shares with each box of ``b`` (M, 4), x0, y0, x1, y1: (N, M)."""
    a, b = _boxes(a), _boxes(b)
    iw = np.clip(np.minimum(a[:, None, 2], b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0]), 0, None)
    ih = np.clip(np.minimum(a[:, None, 3], b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1]), 0, None)
    return iw * ih


def iou_matrix(a: Any, b: Any, eps: float = 0.0) -> np.ndarray:
    """Pairwise IoU of boxes ``a`` (N, 4) and ``b`` (M, 4), x0, y0, x1, y1: the one IoU of rollcam.

    With ``eps`` 0 it is exact, and 0 where the union is empty; ``eps`` > 0 is Ultralytics' form,
    intersection / (union + eps), which the evaluation's P and R follow (rollcam.host.evaluation.metrics).
    """
    inter = intersections(a, b)
    union = box_areas(a)[:, None] + box_areas(b)[None, :] - inter
    if eps:
        return inter / (union + eps)
    return np.where(union > 0, inter / np.maximum(union, 1e-12), 0.0)


def ioa_matrix(a: Any, b: Any, eps: float = 0.0) -> np.ndarray:
    """Pairwise intersection over the area of ``a``'s box (N, M): how much of each box of ``a`` lies inside each
    box of ``b`` (COCO's and Caltech's overlap with a crowd or ignore region). With ``eps`` 0 it is 0 for a box
    of no area; ``eps`` > 0 divides by (area + eps) instead."""
    inter = intersections(a, b)
    area = box_areas(a)[:, None]
    if eps:
        return inter / (area + eps)
    return np.where(area > 0, inter / np.maximum(area, 1e-12), 0.0)


def nms(boxes: np.ndarray, scores: np.ndarray, classes: np.ndarray, iou_threshold: float,
        max_det: int = 300) -> np.ndarray:
    """Indices kept by class-aware greedy non-maximum suppression, best score first (ties in input order).

    A box is dropped when a better-scoring kept box of the same class overlaps it by IoU above
    ``iou_threshold``; at most ``max_det`` are kept. One compiled pass costs O(kept x candidates) without
    temporaries (a noise frame's 600 candidates take well under a millisecond).
    """
    b = np.asarray(boxes, np.float32).reshape(-1, 4)
    if not len(b):
        return np.zeros(0, np.int64)
    order = np.argsort(-np.asarray(scores).reshape(-1), kind="stable")
    c = np.asarray(classes).reshape(-1).astype(np.int64)
    kept = _greedy_nms(np.ascontiguousarray(b[order], np.float64), np.ascontiguousarray(c[order]),
                       float(iou_threshold), int(max_det))
    return order[kept]


@njit(cache=True, nogil=True)
def _greedy_nms(b: np.ndarray, cls: np.ndarray, thr: float, max_det: int) -> np.ndarray:
    """Positions kept in score-sorted boxes ``b`` of classes ``cls`` (the loop of ``nms``)."""
    n = b.shape[0]
    area = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    gone = np.zeros(n, np.bool_)
    out = np.empty(min(n, max(max_det, 0)), np.int64)
    k = 0
    for i in range(n):
        if k >= max_det:
            break
        if gone[i]:
            continue
        out[k] = i
        k += 1
        for j in range(i + 1, n):
            if gone[j] or cls[j] != cls[i]:
                continue
            iw = min(b[i, 2], b[j, 2]) - max(b[i, 0], b[j, 0])
            ih = min(b[i, 3], b[j, 3]) - max(b[i, 1], b[j, 1])
            if not (iw > 0.0 and ih > 0.0):
                continue
            inter = iw * ih
            union = area[i] + area[j] - inter
            if union > 0.0 and inter / max(union, 1e-12) > thr:
                gone[j] = True
    return out[:k]


def tile_windows(width: int, height: int, cols: int, rows: int, overlap: float) -> Iterator[tuple[int, int, int, int]]:
    """``cols`` x ``rows`` windows (x0, y0, x1, y1) covering the image, neighbours overlapping by ``overlap``.

    Tiles let a detector with a small input (300 px, 640 px) see small pedestrians of a large frame at a
    usable size; the overlap keeps a person cut by one tile border whole in the next tile.
    """
    def spans(n: int, size: int) -> list[tuple[int, int]]:
        if n == 1:
            return [(0, size)]
        length = size / (n - (n - 1) * overlap)
        step = length * (1 - overlap)
        return [(round(k * step), min(round(k * step + length), size)) for k in range(n)]

    for y0, y1 in spans(rows, height):
        for x0, x1 in spans(cols, width):
            yield x0, y0, x1, y1



def suppress_contained(boxes: np.ndarray, scores: np.ndarray, classes: np.ndarray,
                       ios_threshold: float = 0.5) -> np.ndarray:
    """Indices kept (best first) when, best score first, a box removes every lower-scoring box of its class
    whose intersection with it is at least ``ios_threshold`` of the smaller one's area (intersection over
    smaller, as SAHI matches sliced predictions): one of the two lies mostly inside the other. Tiled detection
    needs it: a person a tile border cuts is found there as a piece, and the whole frame or the next tile finds
    the whole person around it; the piece and the whole overlap by less than an IoU threshold, so NMS keeps
    both."""
    b = np.asarray(boxes, np.float64).reshape(-1, 4)
    s = np.asarray(scores, np.float64).reshape(-1)
    c = np.asarray(classes).reshape(-1)
    if not len(b):
        return np.zeros(0, np.int64)
    iw = np.clip(np.minimum(b[:, None, 2], b[None, :, 2]) - np.maximum(b[:, None, 0], b[None, :, 0]), 0, None)
    ih = np.clip(np.minimum(b[:, None, 3], b[None, :, 3]) - np.maximum(b[:, None, 1], b[None, :, 1]), 0, None)
    area = np.maximum((b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1]), 1e-12)
    inside = (iw * ih >= ios_threshold * np.minimum(area[:, None], area[None, :])) & (c[:, None] == c[None, :])
    order = np.argsort(-s, kind="stable")
    alive = np.ones(len(b), bool)
    for i in order:
        if alive[i]:
            gone = inside[i] & alive
            gone[i] = False
            alive &= ~gone
    return order[alive[order]]


guard(__name__)
