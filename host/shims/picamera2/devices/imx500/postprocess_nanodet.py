"""picamera2's decoder of NanoDet-Plus (416x416) raw outputs: per anchor, 80 class logits then 4 x 8 bins of a
discrete distance distribution (GFL), over strides 8, 16, 32 and 64."""

from __future__ import annotations

import numpy as np

from .postprocess import combined_nms, softmax

INPUT = 416
STRIDES = (8, 16, 32, 64)
REG_MAX = 7
NUM_CLASSES = 80


def anchors(size: int = INPUT, strides: tuple[int, ...] = STRIDES) -> np.ndarray:
    """(1, N, 4) anchors: x, y of each cell's corner (rows of cells in turn), the stride twice."""
    out = []
    for s in strides:
        n = int(np.ceil(size / s))
        grid = np.arange(n) * s
        xs, ys = np.meshgrid(grid, grid)
        out.append(np.stack([xs.ravel(), ys.ravel(), np.full(n * n, s), np.full(n * n, s)], axis=-1))
    return np.concatenate(out)[None].astype(np.float64)


def postprocess_nanodet_detection(outputs: np.ndarray, conf: float = 0.0, iou_thres: float = 0.65,
                                  max_out_dets: int = 300) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Raw outputs (batch, N, 80 + 32) -> per image (boxes y0 x0 y1 x1 in input pixels, scores, classes)."""
    scores = 1 / (1 + np.exp(-outputs[..., :NUM_CLASSES]))
    bins = softmax(outputs[..., NUM_CLASSES:].reshape(outputs.shape[0], -1, 4, REG_MAX + 1))
    a = anchors()
    dist = (bins @ np.arange(REG_MAX + 1, dtype=np.float32)) * a[..., 2:3]  # left, top, right, bottom
    w, h = dist[..., 0] + dist[..., 2], dist[..., 1] + dist[..., 3]
    xc, yc = a[..., 0] - dist[..., 0] + w / 2, a[..., 1] - dist[..., 1] + h / 2
    return combined_nms(np.stack([xc, yc, w, h], axis=-1), scores, iou_thres, conf, max_out_dets)
