"""The Frame every source yields, emulated or real, and the per-object ground truth of synthetic frames."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .timing import Readout

if TYPE_CHECKING:
    from .imu import ImuSamples
    from .insensor import InSensorResult
    from .pose import Kinematics

Box = tuple[float, float, float, float]
"""An axis-aligned box ``(x0, y0, x1, y1)`` in pixels; x1 and y1 are exclusive edges."""


@dataclass(frozen=True)
class ObjectTruth:
    """Exact ground truth of one object in one frame.

    ``box_gs`` is the object's box with every line at the frame's reference time (its first line's sample
    time); ``box_rs`` the union of its per-line extents with each line at that line's own sample time. Boxes
    are clipped to the image; either is ``None`` when the object has no pixel in it under that shutter.
    Extents are exact along a line and sampled at line centres across lines (rows for row readout,
    columns for column readout), so y0/y1 of a row-read frame are whole rows.
    ``visible`` is the fraction of the object's in-image pixels (in this frame's own shutter) that no nearer
    object hides.
    """

    id: int
    cls: str
    box_gs: Box | None
    box_rs: Box | None
    visible: float
    speed_mps: float

    def to_json(self) -> dict[str, Any]:
        """Plain-JSON form used by ``frames.jsonl``."""

        def r(b: Box | None) -> list[float] | None:
            return None if b is None else [round(float(v), 3) for v in b]

        return {
            "id": self.id,
            "class": self.cls,
            "box_gs": r(self.box_gs),
            "box_rs": r(self.box_rs),
            "visible": round(float(self.visible), 4),
            "speed_mps": round(float(self.speed_mps), 4),
        }


@dataclass(frozen=True, eq=False)
class Frame:
    """One captured image and its timing.

    ``timestamp_ns`` is the start of exposure of the first line read, in the device clock. ``row_times_ns``
    holds the sample time of every image line (row, or column when ``readout`` is by column) in int64 ns;
    ``line_time_ns`` is the nominal line time rounded to whole ns (0 for a global shutter). ``data`` is laid
    out as ``format`` says (``rollcam.sim.formats``); ``size`` (width, height) is the image size in pixels.
    With an IMU (``rollcam.sim.imu``), ``imu`` holds the samples the device delivered with this frame and, for
    synthetic frames, ``poses`` the camera's true kinematics at every line's sample time (``rollcam.sim.pose``).
    With an in-sensor network (``rollcam.sim.insensor``), ``insensor`` holds the results that completed on the
    device clock since the previous frame (each names its own source frame); None when the camera has none.
    """

    data: np.ndarray
    format: str
    sequence: int
    timestamp_ns: int
    line_time_ns: int
    readout: Readout
    exposure_ns: int
    shutter: str = "rolling"
    row_times_ns: np.ndarray | None = field(default=None, repr=False)
    objects: tuple[ObjectTruth, ...] | None = field(default=None, repr=False)
    meta: dict[str, Any] = field(default_factory=dict, repr=False)
    size: tuple[int, int] | None = field(default=None, repr=False)
    imu: ImuSamples | None = field(default=None, repr=False)
    poses: Kinematics | None = field(default=None, repr=False)
    insensor: tuple[InSensorResult, ...] | None = field(default=None, repr=False)

    @property
    def height(self) -> int:
        """Image height in pixels (``size`` when given: packed and planar layouts differ from the shape)."""
        return int(self.size[1]) if self.size is not None else int(self.data.shape[0])

    @property
    def width(self) -> int:
        """Image width in pixels (``size`` when given, e.g. for CSI-2 packed data of bytesperline columns)."""
        return int(self.size[0]) if self.size is not None else int(self.data.shape[1])

    @property
    def bytesperline(self) -> int | None:
        """V4L2 ``bytesperline`` of the first plane when the format is one rollcam knows, else None."""
        from .formats import FORMATS

        f = FORMATS.get(self.format)
        return None if f is None else f.bytesperline(self.width)

    def __repr__(self) -> str:
        n_obj = "-" if self.objects is None else len(self.objects)
        return (
            f"Frame(seq={self.sequence}, t={self.timestamp_ns} ns, {self.width}x{self.height} {self.format}, "
            f"{self.shutter}, line={self.line_time_ns} ns, {self.readout.value}, objects={n_obj})"
        )

    def to_json(self, file: str | None = None) -> dict[str, Any]:
        """Metadata as one ``frames.jsonl`` record (pixel data excluded)."""
        rec: dict[str, Any] = {
            "sequence": self.sequence,
            "shutter": self.shutter,
            "timestamp_ns": int(self.timestamp_ns),
            "line_time_ns": int(self.line_time_ns),
            "exposure_ns": int(self.exposure_ns),
            "readout": self.readout.value,
            "width": self.width,
            "height": self.height,
            "format": self.format,
            "bytesperline": self.bytesperline,
            "dtype": str(self.data.dtype),
            "file": file,
        }
        if self.imu is not None:
            rec["imu_samples"] = len(self.imu)
        if self.insensor is not None:
            rec["insensor"] = [r.to_json() for r in self.insensor]
        if self.objects is not None:
            rec["objects"] = [o.to_json() for o in self.objects]
        rec.update(self.meta)
        return rec
