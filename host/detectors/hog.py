"""``hog``: OpenCV's HOG people detector (Dalal-Triggs, INRIA-trained linear SVM), no model file needed.

Options: ``scale`` (pyramid step, default 1.05), ``stride`` (window stride in px, default 8), ``padding``
(px, default 16), ``hit`` (SVM hit threshold, default 0), ``upscale`` (resize factor applied first, so people
shorter than the 128 px window can be found; default 1). HOG returns its 64x128 window, which frames a person
loosely; boxes are shrunk by 15 % of the width per side and 5 % of the height at top and bottom, the fixed
shrink of OpenCV's ``samples/python/peopledetect.py``. Scores are SVM margins (not probabilities).
"""

from __future__ import annotations

from typing import ClassVar, Literal

import cv2
import numpy as np
from rollcam.common.values import finite_float, non_negative_int, positive_float, positive_int

from .base import PERSON, Detections, DetectorSpec

SHRINK_W, SHRINK_H = 0.15, 0.05


class HogDetector:
    """OpenCV's stock HOG + linear-SVM people detector on BGR images."""

    name = "hog"
    input: Literal["bgr", "raw"] = "bgr"
    class_names: ClassVar[dict[int, str]] = {PERSON: "person"}

    def __init__(self, *, scale: float = 1.05, stride_px: int = 8, padding_px: int = 16,
                 hit_threshold: float = 0.0, upscale: float = 1.0) -> None:
        if not scale > 1.0:
            raise ValueError(f"HOG scale must be > 1, got {scale!r}")
        self.scale, self.stride_px, self.padding_px = scale, stride_px, padding_px
        self.hit_threshold, self.upscale = hit_threshold, upscale
        self._hog = cv2.HOGDescriptor()
        self._hog.setSVMDetector(cv2.HOGDescriptor_getDefaultPeopleDetector())

    def detect(self, image: np.ndarray) -> Detections:
        """Person boxes (shrunk HOG windows) with SVM scores, best first."""
        img = np.asarray(image)
        if img.ndim == 3 and img.shape[2] == 4:
            img = img[:, :, :3]
        if self.upscale != 1.0:
            img = cv2.resize(img, None, fx=self.upscale, fy=self.upscale, interpolation=cv2.INTER_LINEAR)
        win_w, win_h = self._hog.winSize
        if img.shape[0] + 2 * self.padding_px < win_h or img.shape[1] + 2 * self.padding_px < win_w:
            # No window fits (OpenCV would crash the process rather than raise): no person can be found.
            return Detections.empty()
        rects, weights = self._hog.detectMultiScale(
            np.ascontiguousarray(img), hitThreshold=self.hit_threshold,
            winStride=(self.stride_px, self.stride_px), padding=(self.padding_px, self.padding_px), scale=self.scale)
        rects = np.asarray(rects, dtype=np.float32).reshape(-1, 4)
        if not len(rects):
            return Detections.empty()
        x, y, w, h = rects.T
        dx, dy = SHRINK_W * w, SHRINK_H * h
        boxes = np.stack([x + dx, y + dy, x + w - dx, y + h - dy], axis=1) / self.upscale
        scores = np.asarray(weights, dtype=np.float32).reshape(-1)
        return Detections(boxes, scores, np.full(len(scores), PERSON, np.int32)).sorted()

    def close(self) -> None:
        """Nothing to release; present for the protocol."""

    def __repr__(self) -> str:
        return f"HogDetector(scale={self.scale}, stride_px={self.stride_px}, upscale={self.upscale})"


def open_detector(spec: DetectorSpec) -> HogDetector:
    """Build a HOG detector from ``hog?scale=..&stride=..&padding=..&hit=..&upscale=..``."""
    spec.check({"scale", "stride", "padding", "hit", "upscale"})
    from rollcam.common.errors import ConfigError

    if spec.target:
        raise ConfigError(f"detector {spec.spec!r}: hog takes no target (got {spec.target!r})")
    scale = spec.get("scale", positive_float, 1.05)
    if not scale > 1.0:
        raise ConfigError(f"detector {spec.spec!r}: option scale={scale!r} is invalid (must be > 1)")
    return HogDetector(scale=scale, stride_px=spec.get("stride", positive_int, 8),
                       padding_px=spec.get("padding", non_negative_int, 16),
                       hit_threshold=spec.get("hit", finite_float, 0.0),
                       upscale=spec.get("upscale", positive_float, 1.0))
