"""``NetworkIntrinsics``: what a network says about itself (task, box layout, labels), as picamera2 has it.

A real ``.rpk`` carries this JSON in its archive; the emulated IMX500 makes it from the rollcam network it runs
(``networks.py``). Scripts read and override it attribute by attribute (the IMX500 examples set every
command-line argument that names one); the checks are picamera2's schema's, as ValueError.
"""

from __future__ import annotations

import json
from typing import Any

TASKS = ("classification", "object detection", "pose estimation", "segmentation")
DEFAULTS = {"inference_rate": 30.0}


class NetworkIntrinsics:
    """A network's intrinsics: ``task``, ``inference_rate`` (``fps``), ``bbox_normalization``, ``bbox_order``,
    ``softmax``, ``postprocess``, ``preserve_aspect_ratio``, ``labels``, ``ignore_dash_labels``."""

    def __init__(self, val: dict[str, Any] | None = None) -> None:
        self._doc: dict[str, Any] | None = None
        if val is not None:
            self.intrinsics = val

    @property
    def intrinsics(self) -> dict[str, Any] | None:
        """The whole JSON document (None when empty)."""
        return self._doc

    @intrinsics.setter
    def intrinsics(self, val: dict[str, Any]) -> None:
        _check(val)
        self._doc = dict(val)

    def __repr__(self) -> str:
        return json.dumps(self._doc) if self._doc else ""

    def update_with_defaults(self) -> None:
        """Fill in what is unset with picamera2's defaults (an inference rate of 30 per second)."""
        self._doc = {**DEFAULTS, **(self._doc or {})}

    def _get(self, key: str, section: str | None = None) -> Any:
        doc = self._doc or {}
        return doc.get(key) if section is None else (doc.get(section) or {}).get(key)

    def _set(self, key: str, value: Any, section: str | None = None) -> None:
        doc = dict(self._doc or {})
        if section is None:
            doc[key] = value
        else:
            doc[section] = {**(doc.get(section) or {}), key: value}
        _check(doc)
        self._doc = doc

    def _drop(self, key: str, section: str | None = None) -> None:
        if not self._doc:
            return
        if section is None:
            self._doc.pop(key, None)
        elif section in self._doc:
            self._doc[section].pop(key, None)
            if not self._doc[section]:
                self._doc.pop(section)

    def _flag(self, key: str, val: bool | None, section: str) -> None:
        if val is None:
            return
        if val:
            self._set(key, bool(val), section)
        else:
            self._drop(key, section)

    @property
    def task(self) -> str | None:
        """The network's task."""
        return self._get("task")

    @task.setter
    def task(self, val: str) -> None:
        self._set("task", val)

    @property
    def inference_rate(self) -> float | None:
        """Inferences per second the network sustains (scripts set the camera's FrameRate to it)."""
        return self._get("inference_rate")

    @inference_rate.setter
    def inference_rate(self, val: float) -> None:
        if val < 0:
            self._drop("inference_rate")
        else:
            self._set("inference_rate", val)

    fps = inference_rate

    @property
    def bbox_normalization(self) -> bool | None:
        """True: boxes come in input-tensor pixels (divide by the input size)."""
        return self._get("bbox_normalization", "cpu")

    @bbox_normalization.setter
    def bbox_normalization(self, val: bool | None) -> None:
        self._flag("bbox_normalization", val, "cpu")

    @property
    def bbox_order(self) -> str | None:
        """``yx`` (y0, x0, y1, x1) or ``xy`` (x0, y0, x1, y1)."""
        return self._get("bbox_order", "cpu")

    @bbox_order.setter
    def bbox_order(self, val: str) -> None:
        if val not in ("xy", "yx"):
            raise ValueError("bbox_order must be either 'xy' or 'yx'")
        self._set("bbox_order", val, "cpu")

    @property
    def softmax(self) -> bool | None:
        """True: the scripts apply a softmax to the output."""
        return self._get("softmax", "cpu")

    @softmax.setter
    def softmax(self, val: bool | None) -> None:
        self._flag("softmax", val, "cpu")

    @property
    def postprocess(self) -> str | None:
        """The host post-processing a network needs (``nanodet``, ...); None for on-chip post-processing."""
        return self._get("post_processing", "cpu")

    @postprocess.setter
    def postprocess(self, val: str) -> None:
        if val:
            self._set("post_processing", val, "cpu")
        else:
            self._drop("post_processing", "cpu")

    @property
    def preserve_aspect_ratio(self) -> bool | None:
        """True when the input must keep the tensor's aspect ratio (scripts call ``set_auto_aspect_ratio``)."""
        ar = self._get("input_aspect_ratio")
        return None if ar is None else ar["width"] == ar["height"]

    @preserve_aspect_ratio.setter
    def preserve_aspect_ratio(self, val: bool | None) -> None:
        if val:
            self._set("input_aspect_ratio", {"width": 1, "height": 1})
        elif val is not None:
            self._drop("input_aspect_ratio")

    @property
    def labels(self) -> list[str] | None:
        """Class names by class id."""
        return self._get("labels", "classes")

    @labels.setter
    def labels(self, val: list[str]) -> None:
        if val:
            self._set("labels", list(val), "classes")
        else:
            self._drop("labels", "classes")

    @property
    def ignore_dash_labels(self) -> bool | None:
        """True: labels named ``-`` (unused class ids) are dropped from the list."""
        return self._get("ignore_undefined", "classes")

    @ignore_dash_labels.setter
    def ignore_dash_labels(self, val: bool | None) -> None:
        self._flag("ignore_undefined", val, "classes")


def _check(doc: Any) -> None:
    """picamera2's schema of the intrinsics, as ValueError naming the bad value."""
    if not isinstance(doc, dict):
        raise ValueError(f"network intrinsics must be a JSON object, got {doc!r}")
    if "task" in doc and doc["task"] not in TASKS:
        raise ValueError(f"task {doc['task']!r} is not one of {list(TASKS)}")
    rate = doc.get("inference_rate", 0)
    if not isinstance(rate, (int, float)) or isinstance(rate, bool) or rate < 0:
        raise ValueError(f"inference_rate {rate!r} must be a number >= 0")
    cpu = doc.get("cpu", {})
    if not isinstance(cpu, dict) or cpu.get("bbox_order", "yx") not in ("xy", "yx"):
        raise ValueError(f"cpu {cpu!r}: bbox_order must be 'xy' or 'yx'")
    ar = doc.get("input_aspect_ratio")
    if ar is not None and not (isinstance(ar, dict) and all(isinstance(ar.get(k), int) and ar[k] > 0
                                                            for k in ("width", "height"))):
        raise ValueError(f"input_aspect_ratio {ar!r} needs positive integer width and height")
    labels = (doc.get("classes") or {}).get("labels", [])
    if not (isinstance(labels, list) and all(isinstance(s, str) for s in labels)):
        raise ValueError(f"labels {labels!r} must be a list of strings")
