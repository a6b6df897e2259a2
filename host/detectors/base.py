"""The detector protocol and its result type, shared by every built-in detector and by evaluation."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal, Protocol, runtime_checkable

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.common.values import convert_option, parse_query, reject_unknown

PERSON = 0
"""Class id of a person (the COCO/YOLO convention: class 0 of the 80 COCO classes)."""


@dataclass(frozen=True)
class Detections:
    """Detections on one image: ``boxes`` (N, 4) float32 x0, y0, x1, y1 in image pixels, ``scores`` (N,)
    float32 in the detector's own confidence scale (higher is surer), ``classes`` (N,) int32 class ids."""

    boxes: np.ndarray
    scores: np.ndarray
    classes: np.ndarray

    def __post_init__(self) -> None:
        boxes = np.asarray(self.boxes, dtype=np.float32).reshape(-1, 4)
        scores = np.asarray(self.scores, dtype=np.float32).reshape(-1)
        classes = np.asarray(self.classes, dtype=np.int32).reshape(-1)
        if not len(boxes) == len(scores) == len(classes):
            raise ValueError(f"Detections: {len(boxes)} boxes, {len(scores)} scores, {len(classes)} classes")
        object.__setattr__(self, "boxes", boxes)
        object.__setattr__(self, "scores", scores)
        object.__setattr__(self, "classes", classes)

    @classmethod
    def empty(cls) -> Detections:
        """No detections."""
        return cls(np.zeros((0, 4), np.float32), np.zeros(0, np.float32), np.zeros(0, np.int32))

    def __len__(self) -> int:
        return len(self.scores)

    def sorted(self) -> Detections:
        """The same detections, highest score first (stable)."""
        order = np.argsort(-self.scores, kind="stable")
        return Detections(self.boxes[order], self.scores[order], self.classes[order])

    def to_json(self) -> list[dict[str, Any]]:
        """One plain dict per detection: ``box`` [x0, y0, x1, y1], ``score``, ``cls``."""
        return [{"box": [round(float(v), 2) for v in b], "score": round(float(s), 5), "cls": int(c)}
                for b, s, c in zip(self.boxes, self.scores, self.classes, strict=True)]

    def __repr__(self) -> str:
        return f"Detections(n={len(self)})"


@runtime_checkable
class Detector(Protocol):
    """What every detector offers. ``input`` says what ``detect`` wants: ``"bgr"`` (8-bit BGR, H x W x 3)
    or ``"raw"`` (the sensor's raw mosaic, ISP-less); ``"device"`` is the ``insensor`` reader, whose detections
    come with the frames (its ``pair(frame)``). ``class_names`` maps class ids to names."""

    name: str
    input: Literal["bgr", "raw", "device"]
    class_names: dict[int, str]

    def detect(self, image: np.ndarray) -> Detections:
        """Detections on one image."""
        ...

    def close(self) -> None:
        """Release the model; safe to call twice."""
        ...


@dataclass(frozen=True)
class DetectorSpec:
    """A parsed detector spec: name, target (a model path for ``onnx:``) and options."""

    spec: str
    name: str
    target: str = ""
    options: dict[str, str] = field(default_factory=dict)

    def check(self, allowed: set[str]) -> None:
        """Reject options this detector does not know, naming them and the ones it does."""
        reject_unknown(self.options, allowed, f"detector {self.spec!r}", ConfigError)

    def get(self, key: str, kind: Any, default: Any = None) -> Any:
        """Option ``key`` converted by ``kind``, or ``default``; a bad value names the option."""
        return convert_option(self.options, key, kind, default, f"detector {self.spec!r}", ConfigError)


def parse_spec(spec: str) -> DetectorSpec:
    """Split ``NAME[:TARGET][?key=value&...]``; duplicate or empty option names are errors."""
    if not isinstance(spec, str) or not spec.strip():
        raise ConfigError(f"detector spec {spec!r} is empty; expected e.g. 'hog' or 'onnx:model.onnx'")
    head, _, query = spec.partition("?")
    name, _, target = head.partition(":")
    options = parse_query(query, f"detector {spec!r}", ConfigError)
    return DetectorSpec(spec, name.strip().lower(), target, options)
