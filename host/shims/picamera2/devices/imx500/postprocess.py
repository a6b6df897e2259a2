"""picamera2's post-processing helpers for IMX500 networks, as numpy functions of the same names and
meanings: greedy NMS, NMS over a batch of class-score heads, box format changes, clipping and scaling to an
image, softmax; and ``COCODrawer``, which draws people's boxes and COCO skeletons. Boxes are (y_min, x_min,
y_max, x_max) unless a function says otherwise.
"""

from __future__ import annotations

from enum import Enum
from typing import Any

import numpy as np

CLASS_OFFSET = 640
"""``combined_nms`` shifts each class's boxes by class id times this, so one NMS pass never merges classes."""


class BoxFormat(Enum):
    """Box layouts ``convert_to_ymin_xmin_ymax_xmax_format`` reads."""

    YMIM_XMIN_YMAX_XMAX = "ymin_xmin_ymax_xmax"
    XMIM_YMIN_XMAX_YMAX = "xmin_ymin_xmax_ymax"
    XMIN_YMIN_W_H = "xmin_ymin_width_height"
    XC_YC_W_H = "xc_yc_width_height"


def softmax(x: np.ndarray) -> np.ndarray:
    """Softmax over the last axis (shifted by its maximum, so large logits do not overflow)."""
    e = np.exp(x - np.max(x, axis=-1, keepdims=True))
    return e / np.sum(e, axis=-1, keepdims=True)


def nms(dets: np.ndarray, scores: np.ndarray, iou_thres: float = 0.55, max_out_dets: int = 50) -> list[int]:
    """Indices of the boxes greedy NMS keeps, best score first (pixel-inclusive areas, as picamera2's)."""
    y0, x0, y1, x1 = (dets[:, i] for i in range(4))
    area = (x1 - x0 + 1) * (y1 - y0 + 1)
    order = np.argsort(scores)[::-1]
    keep: list[int] = []
    while order.size:
        best, rest = order[0], order[1:]
        keep.append(int(best))
        w = np.maximum(0.0, np.minimum(x1[best], x1[rest]) - np.maximum(x0[best], x0[rest]) + 1)
        h = np.maximum(0.0, np.minimum(y1[best], y1[rest]) - np.maximum(y0[best], y0[rest]) + 1)
        inter = w * h
        order = rest[inter / (area[best] + area[rest] - inter) <= iou_thres]
    return keep[:max_out_dets]


def convert_to_ymin_xmin_ymax_xmax_format(boxes: np.ndarray, orig_format: BoxFormat) -> np.ndarray:
    """Boxes of ``orig_format`` as (y_min, x_min, y_max, x_max) (in place, except from centre-size)."""
    if len(boxes) == 0 or orig_format == BoxFormat.YMIM_XMIN_YMAX_XMAX:
        return boxes
    if orig_format == BoxFormat.XC_YC_W_H:
        xc, yc, w, h = (boxes[:, i].copy() for i in range(4))
        out = np.copy(boxes)
        out[:, 0], out[:, 1], out[:, 2], out[:, 3] = yc - h / 2, xc - w / 2, yc + h / 2, xc + w / 2
        return out
    if orig_format == BoxFormat.XMIN_YMIN_W_H:
        boxes[:, 2] += boxes[:, 0]
        boxes[:, 3] += boxes[:, 1]
    if orig_format in (BoxFormat.XMIN_YMIN_W_H, BoxFormat.XMIM_YMIN_XMAX_YMAX):
        boxes[:, [0, 1, 2, 3]] = boxes[:, [1, 0, 3, 2]]
        return boxes
    raise ValueError(f"Unsupported boxes format {orig_format!r}")


def combined_nms(batch_boxes: np.ndarray, batch_scores: np.ndarray, iou_thres: float = 0.65, conf: float = 0.55,
                 max_out_dets: int = 50) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per image of a batch: centre-size boxes and per-class scores -> (boxes y0 x0 y1 x1, scores, classes)
    above ``conf`` after NMS within each class."""
    out = []
    for boxes, scores in zip(batch_boxes, batch_scores, strict=True):
        cls = np.argmax(scores, axis=1)
        best = np.max(scores, axis=1)
        x = np.concatenate([boxes, best[:, None], cls[:, None]], axis=1)[best > conf]
        x = x[np.argsort(-x[:, 4], kind="stable")[:8400]]
        x[:, :4] = convert_to_ymin_xmin_ymax_xmax_format(x[:, :4], BoxFormat.XC_YC_W_H)
        keep = nms(x[:, :4] + x[:, 5:6] * CLASS_OFFSET, x[:, 4], iou_thres=iou_thres, max_out_dets=max_out_dets)
        x = x[keep]
        out.append((x[:, :4], x[:, 4], x[:, 5]))
    return out


def clip_boxes(boxes: np.ndarray, h: int, w: int) -> np.ndarray:
    """Boxes clipped to an ``h`` x ``w`` image (in place)."""
    boxes[..., [0, 2]] = np.clip(boxes[..., [0, 2]], 0, h)
    boxes[..., [1, 3]] = np.clip(boxes[..., [1, 3]], 0, w)
    return boxes


def scale_boxes(boxes: np.ndarray, h_image: int, w_image: int, h_model: int, w_model: int,
                preserve_aspect_ratio: bool, normalized: bool = True) -> np.ndarray:
    """Boxes from a ``w_model`` x ``h_model`` input (normalised to it unless ``normalized`` is False) to an
    image's pixels; ``preserve_aspect_ratio``: the input was letterboxed. Like picamera2's, it scales
    coordinates 0 and 2 by the width and 1 and 3 by the height."""
    sh, sw = h_image / h_model, w_image / w_model
    dh = dw = 0
    if preserve_aspect_ratio:
        sh = sw = max(sh, sw)
        dh = int((h_model - int(np.round(h_image / sh))) / 2)
        dw = int((w_model - int(np.round(w_image / sw))) / 2)
    nh, nw = (h_model, w_model) if normalized else (1, 1)
    boxes[..., [0, 2]] = (boxes[..., [0, 2]] * nw - dw) * sw
    boxes[..., [1, 3]] = (boxes[..., [1, 3]] * nh - dh) * sh
    return clip_boxes(boxes, h_image, w_image)


COCO_SKELETON = ((0, 1), (0, 2), (1, 3), (2, 4), (5, 6), (5, 7), (7, 9), (6, 8), (8, 10), (5, 11), (6, 12),
                 (11, 12), (11, 13), (12, 14), (13, 15), (14, 16))
"""The limbs between COCO's 17 keypoints."""


class COCODrawer:
    """Draws pose results on an image as picamera2's does: each person's box with its category and score, and
    its keypoints above a confidence joined by COCO's limbs. ``needs_rescale_coords``: boxes and keypoints are
    normalised to the pixel array (``IMX500.convert_inference_coords`` maps them into the stream); else they are
    in the image's pixels already (a box as y0, x0, y1, x1; keypoints as flat x, y, score triples)."""

    def __init__(self, categories: list[str], imx500: Any, needs_rescale_coords: bool = True) -> None:
        self.categories = categories
        self.imx500 = imx500
        self.needs_rescale_coords = needs_rescale_coords

    def get_coords(self, annotation: Any, metadata: dict, picam2: Any, stream: str) -> tuple[int, int, int, int]:
        """A box as (y0, x0, y1, x1) in the image's pixels."""
        if self.needs_rescale_coords:
            x, y, w, h = self.imx500.convert_inference_coords(annotation, metadata, picam2, stream)
            return int(y), int(x), int(y + h), int(x + w)
        y0, x0, y1, x1 = annotation
        return int(max(0, y0)), int(max(0, x0)), int(y1), int(x1)

    def draw_bounding_box(self, img: np.ndarray, annotation: Any, class_id: Any, score: float, metadata: dict,
                          picam2: Any, stream: str) -> None:
        """One person's box, labelled with its category and score."""
        import cv2

        y0, x0, y1, x1 = self.get_coords(annotation, metadata, picam2, stream)
        cv2.rectangle(img, (x0, y0), (x1, y1), (0, 0, 255), 2)
        cv2.putText(img, f"{self.categories[int(class_id)]}:{score:.3f}", (x0, y0), cv2.FONT_HERSHEY_SIMPLEX,
                    0.5, (0, 255, 0), 1)

    def draw_keypoints(self, img: np.ndarray, keypoints: Any, min_confidence: float, metadata: dict, picam2: Any,
                       stream: str) -> None:
        """One person's keypoints above ``min_confidence`` and the limbs between them."""
        import cv2

        pts = np.asarray(keypoints, np.float64).reshape(-1, 3)
        points = {}
        for i, (x, y, conf) in enumerate(pts):
            if conf < min_confidence:
                continue
            if self.needs_rescale_coords:
                px, py, _, _ = self.imx500.convert_inference_coords((y, x, y, x), metadata, picam2, stream)
            else:
                px, py = int(x), int(y)
            points[i] = (int(px), int(py))
            cv2.circle(img, points[i], 3, (0, 255, 0), -1)
        for a, b in COCO_SKELETON:
            if a in points and b in points:
                cv2.line(img, points[a], points[b], (255, 255, 0), 2)

    def annotate_image(self, img: np.ndarray, b: Any, s: Any, c: Any, k: Any, box_min_conf: float,
                       kps_min_conf: float, metadata: dict, picam2: Any, stream: str) -> None:
        """Boxes ``b`` with scores ``s`` and classes ``c`` above ``box_min_conf``, keypoints ``k`` (one flat list or
        (17, 3) array a person) above ``kps_min_conf``."""
        for index, row in enumerate(k):
            if s[index] >= box_min_conf:
                self.draw_bounding_box(img, b[index], c[index], s[index], metadata, picam2, stream)
                self.draw_keypoints(img, row, kps_min_conf, metadata, picam2, stream)
