"""Training targets and losses of the person detector (TTFNet's recipe on CenterNet's heatmap).

Targets, per image, on the stride-4 grid (numpy, so they are built beside the batch and are deterministic):

- ``heat``: each labelled box puts an elliptical Gaussian on the grid, peak 1 at the cell holding its centre,
  sigmas ``alpha * (w, h) / 6`` (TTFNet's alpha = 0.54: the Gaussian follows the box's aspect, which for a
  walker is tall and narrow); the map is the maximum over boxes.
- ``reg`` / ``weight``: every cell inside a box where that box's Gaussian exceeds ``REG_MIN`` regresses the box
  (the smallest box wins a shared cell), weighted by the Gaussian so the centre counts most; each box's
  weights sum to log(area) (TTFNet), so large people do not drown small ones nor the reverse.
- ``ignore``: cells whose centre lies in an ignore region (COCO ``iscrowd``: a person too small or too hidden
  to label) carry no heatmap loss; the detector is neither taught to find nor to miss them.

Losses: CenterNet's penalty-reduced focal loss on the heatmap (normalised by the number of boxes), GIoU on the
boxes (normalised by the weights).
"""

from __future__ import annotations

import numpy as np
import torch

from .model import STRIDE, decode_boxes

ALPHA = 0.54
REG_MIN = 0.05
BOX_LOSS_WEIGHT = 5.0


def build_targets(boxes: np.ndarray, ignore: np.ndarray, grid_h: int, grid_w: int) -> dict[str, np.ndarray]:
    """Targets of one image: ``boxes`` (N, 4) x0, y0, x1, y1 in network-input pixels, ``ignore`` (N,) bool."""
    heat = np.zeros((grid_h, grid_w), np.float32)
    reg = np.zeros((4, grid_h, grid_w), np.float32)
    weight = np.zeros((grid_h, grid_w), np.float32)
    area_of = np.full((grid_h, grid_w), np.inf, np.float32)
    mask = np.ones((grid_h, grid_w), np.float32)
    xs = (np.arange(grid_w, dtype=np.float32) + 0.5) * STRIDE
    ys = (np.arange(grid_h, dtype=np.float32) + 0.5) * STRIDE
    boxes = np.asarray(boxes, np.float32).reshape(-1, 4)
    ignore = np.asarray(ignore, bool).reshape(-1)
    for (x0, y0, x1, y1), ig in zip(boxes, ignore, strict=True):
        if x1 <= x0 or y1 <= y0:
            continue
        inside = (xs[None, :] >= x0) & (xs[None, :] <= x1) & (ys[:, None] >= y0) & (ys[:, None] <= y1)
        if ig:
            mask[inside] = 0.0
            continue
        cx_cell = min(int((x0 + x1) / 2 / STRIDE), grid_w - 1)
        cy_cell = min(int((y0 + y1) / 2 / STRIDE), grid_h - 1)
        sx = max(ALPHA * (x1 - x0) / STRIDE / 6, 1e-3)
        sy = max(ALPHA * (y1 - y0) / STRIDE / 6, 1e-3)
        gx = np.exp(-((np.arange(grid_w) - cx_cell) ** 2) / (2 * sx * sx)).astype(np.float32)
        gy = np.exp(-((np.arange(grid_h) - cy_cell) ** 2) / (2 * sy * sy)).astype(np.float32)
        g = gy[:, None] * gx[None, :]
        np.maximum(heat, g, out=heat)
        heat[cy_cell, cx_cell] = 1.0
        area = (x1 - x0) * (y1 - y0)
        cells = ((g > REG_MIN) & inside) | _one_cell(grid_h, grid_w, cy_cell, cx_cell)
        cells &= area < area_of
        if not cells.any():
            continue
        w = g * cells
        w *= np.log(max(area, 2.0)) / w.sum()
        area_of[cells] = area
        reg[:, cells] = np.array([x0, y0, x1, y1], np.float32)[:, None]
        weight[cells] = w[cells]
    mask[heat >= 1.0] = 1.0  # a labelled centre inside someone else's ignore region still counts
    return {"heat": heat[None], "reg": reg, "weight": weight[None], "mask": mask[None],
            "n_pos": np.float32((heat >= 1.0).sum())}


def _one_cell(h: int, w: int, y: int, x: int) -> np.ndarray:
    m = np.zeros((h, w), bool)
    m[y, x] = True
    return m


def focal_loss(logits: torch.Tensor, heat: torch.Tensor, mask: torch.Tensor, n_pos: torch.Tensor) -> torch.Tensor:
    """CenterNet's penalty-reduced focal loss (alpha 2, beta 4), normalised by the number of box centres."""
    p = torch.sigmoid(logits).clamp(1e-4, 1 - 1e-4)
    pos = (heat >= 1.0).to(p.dtype)
    pos_loss = -torch.log(p) * (1 - p) ** 2 * pos
    neg_loss = -torch.log(1 - p) * p ** 2 * (1 - heat) ** 4 * (1 - pos) * mask
    return (pos_loss.sum() + neg_loss.sum()) / n_pos.sum().clamp(min=1.0)


def giou_loss(box: torch.Tensor, reg: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """Weighted GIoU loss of the decoded boxes against their targets over the regressing cells."""
    pred = decode_boxes(box)
    px0, py0, px1, py1 = pred.unbind(1)
    tx0, ty0, tx1, ty1 = reg.unbind(1)
    w = weight[:, 0]
    iw = (torch.min(px1, tx1) - torch.max(px0, tx0)).clamp(min=0)
    inter = iw * (torch.min(py1, ty1) - torch.max(py0, ty0)).clamp(min=0)
    union = (px1 - px0) * (py1 - py0) + (tx1 - tx0) * (ty1 - ty0) - inter
    iou = inter / union.clamp(min=1e-6)
    hull = (torch.max(px1, tx1) - torch.min(px0, tx0)) * (torch.max(py1, ty1) - torch.min(py0, ty0))
    giou = iou - (hull - union) / hull.clamp(min=1e-6)
    return ((1 - giou) * w).sum() / w.sum().clamp(min=1e-6)


def detector_loss(outputs: tuple[torch.Tensor, torch.Tensor], targets: dict[str, torch.Tensor]
                  ) -> tuple[torch.Tensor, dict[str, float]]:
    """Total loss of a batch and its parts (``heat``, ``box``) as floats for the log."""
    logits, box = outputs
    lh = focal_loss(logits, targets["heat"], targets["mask"], targets["n_pos"])
    lb = giou_loss(box, targets["reg"], targets["weight"])
    total = lh + BOX_LOSS_WEIGHT * lb
    return total, {"heat": float(lh.detach()), "box": float(lb.detach())}
