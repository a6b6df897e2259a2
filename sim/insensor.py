"""What an intelligent vision sensor's on-chip network delivers: one result per frame it ran on.

``InSensorResult`` is the one result type of the in-sensor inference stage (``rollcam.firmware.insensor``):
the detections (boxes in the source frame's pixels, scores, class ids), the network's raw output tensors, and
when it was made, all in integer ns of the device clock: the source frame's sequence number and row timing
(start of exposure of its first line, line time, readout, exposure), the IMX500 input tensor the network ran
on when it takes one (``input_tensor``; ``injected``: a tensor put in the frame's place), ``input_ns`` (the
frame was whole on the chip: its last line's end of exposure) and ``done_ns`` (the modelled accelerator latency
later). A frame carries (``Frame.insensor``) the results that completed since the previous frame was
delivered, so a result usually rides on a later frame than the one it came from; ``seq`` says which. Plain data
(numpy arrays), so every layer and transport can hold it; ``to_json``/``from_json`` are its wire form.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

INPUTS = ("raw", "isp")
"""What the network ran on: the raw mosaic (no ISP) or the ISP's picture."""


@dataclass(frozen=True, eq=False)
class InSensorResult:
    """One network run on frame ``seq`` (see the module docstring); boxes are x0, y0, x1, y1 in the frame's
    pixels (x1, y1 exclusive)."""

    seq: int
    boxes: np.ndarray
    scores: np.ndarray
    classes: np.ndarray
    timestamp_ns: int
    line_time_ns: int
    readout: str
    exposure_ns: int
    input_ns: int
    done_ns: int
    input: str = "raw"
    input_size: tuple[int, int] = (0, 0)
    macs: int = 0
    network: str = ""
    tensors: tuple[tuple[str, np.ndarray], ...] = field(default=(), repr=False)
    input_tensor: np.ndarray | None = field(default=None, repr=False)
    injected: bool = False

    def __post_init__(self) -> None:
        fix = object.__setattr__
        fix(self, "boxes", np.asarray(self.boxes, np.float32).reshape(-1, 4))
        fix(self, "scores", np.asarray(self.scores, np.float32).reshape(-1))
        fix(self, "classes", np.asarray(self.classes, np.int32).reshape(-1))
        if not len(self.boxes) == len(self.scores) == len(self.classes):
            raise ValueError(f"InSensorResult: {len(self.boxes)} boxes, {len(self.scores)} scores, "
                             f"{len(self.classes)} classes")
        if self.input not in INPUTS:
            raise ValueError(f"InSensorResult: input {self.input!r} is not one of {INPUTS}")
        if self.done_ns < self.input_ns:
            raise ValueError(f"InSensorResult: done_ns {self.done_ns} is before input_ns {self.input_ns}")

    @property
    def latency_ns(self) -> int:
        """Modelled accelerator time: input complete to result ready."""
        return self.done_ns - self.input_ns

    def __len__(self) -> int:
        return len(self.scores)

    def __repr__(self) -> str:
        return (f"InSensorResult(seq={self.seq}, n={len(self)}, {self.input} {self.input_size[0]}x"
                f"{self.input_size[1]}, input {self.input_ns} ns, done {self.done_ns} ns)")

    def tensor_bytes(self) -> int:
        """Bytes of the raw output tensors (what a metadata-only sensor sends besides a small header)."""
        return int(sum(t.nbytes for _, t in self.tensors))

    def to_json(self, tensors: bool = False) -> dict[str, Any]:
        """Plain JSON: detections as ``{box, score, cls}``, the timing, and (``tensors``) the output tensors as
        ``{name: {shape, dtype, data}}`` with data a flat list."""
        doc: dict[str, Any] = {
            "seq": self.seq, "network": self.network, "input": self.input,
            "input_size": list(self.input_size), "macs": self.macs,
            "timestamp_ns": int(self.timestamp_ns), "line_time_ns": int(self.line_time_ns),
            "readout": self.readout, "exposure_ns": int(self.exposure_ns),
            "input_ns": int(self.input_ns), "done_ns": int(self.done_ns),
            "detections": [{"box": [round(float(v), 2) for v in b], "score": round(float(s), 5), "cls": int(c)}
                           for b, s, c in zip(self.boxes, self.scores, self.classes, strict=True)],
            "tensor_shapes": {n: list(t.shape) for n, t in self.tensors}, "injected": self.injected,
        }
        if tensors:
            doc["tensors"] = {n: {"shape": list(t.shape), "dtype": str(t.dtype), "data": t.ravel().tolist()}
                              for n, t in self.tensors}
            if self.input_tensor is not None:
                doc["input_tensor"] = {"dtype": str(self.input_tensor.dtype), "data": self.input_tensor.tolist()}
        return doc

    @classmethod
    def from_json(cls, doc: dict[str, Any]) -> InSensorResult:
        """The result ``to_json`` wrote (tensors only when it wrote them)."""
        dets = doc.get("detections", [])
        tensors = tuple((n, np.asarray(t["data"], dtype=t["dtype"]).reshape(t["shape"]))
                        for n, t in (doc.get("tensors") or {}).items())
        given = doc.get("input_tensor")
        input_tensor = None if given is None else np.asarray(given["data"], dtype=given["dtype"])
        return cls(seq=int(doc["seq"]), boxes=[d["box"] for d in dets], scores=[d["score"] for d in dets],
                   classes=[d["cls"] for d in dets], timestamp_ns=int(doc["timestamp_ns"]),
                   line_time_ns=int(doc["line_time_ns"]), readout=str(doc["readout"]),
                   exposure_ns=int(doc["exposure_ns"]), input_ns=int(doc["input_ns"]), done_ns=int(doc["done_ns"]),
                   input=str(doc.get("input", "raw")), input_size=tuple(doc.get("input_size", (0, 0))),
                   macs=int(doc.get("macs", 0)), network=str(doc.get("network", "")), tensors=tensors,
                   input_tensor=input_tensor, injected=bool(doc.get("injected", False)))
