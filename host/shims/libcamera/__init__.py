"""A small stand-in for libcamera's Python bindings, enough for picamera2 scripts run on rollcam.

It exists beside rollcam's ``picamera2`` stand-in (``rollcam.host.shims_path()``) because picamera2 scripts
import from it: ``from libcamera import Transform, ColorSpace, controls`` (``controls.AfModeEnum.Continuous``,
``controls.draft.NoiseReductionModeEnum.Fast``). It has no cameras of its own: the camera is picamera2's.
"""

from __future__ import annotations

import enum
from types import SimpleNamespace
from typing import Any, NamedTuple

__all__ = ["ColorSpace", "Rectangle", "Size", "Transform", "controls"]


class Size(NamedTuple):
    """A width and height in pixels."""

    width: int
    height: int

    def to_tuple(self) -> tuple[int, int]:
        return (self.width, self.height)


class Rectangle(NamedTuple):
    """A rectangle: top-left corner and size, in pixels."""

    x: int
    y: int
    width: int
    height: int

    def to_tuple(self) -> tuple[int, int, int, int]:
        return (self.x, self.y, self.width, self.height)


class Transform:
    """An image transform: horizontal and vertical flips (``transpose`` is accepted but no Pi sensor has it)."""

    def __init__(self, other: Transform | None = None, *, hflip: int = 0, vflip: int = 0, transpose: int = 0,
                 rotation: int = 0) -> None:
        if other is not None:
            hflip, vflip, transpose = other.hflip, other.vflip, other.transpose
        if rotation not in (0, 180):
            raise ValueError(f"rotation {rotation!r} is not 0 or 180")
        if rotation == 180:
            hflip, vflip = not hflip, not vflip
        self.hflip, self.vflip, self.transpose = bool(hflip), bool(vflip), bool(transpose)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Transform) and (self.hflip, self.vflip, self.transpose) == (
            other.hflip, other.vflip, other.transpose)

    def __hash__(self) -> int:
        return hash((self.hflip, self.vflip, self.transpose))

    def __repr__(self) -> str:
        flags = [n for n in ("hflip", "vflip", "transpose") if getattr(self, n)]
        return f"<libcamera.Transform '{'/'.join(flags) or 'identity'}'>"


_COLOUR_SPACE_FIELDS: dict[str, tuple[str, str, str, str]] = {
    "Sycc": ("Rec709", "Srgb", "Rec601", "Full"), "Smpte170m": ("Smpte170m", "Rec709", "Rec601", "Limited"),
    "Rec709": ("Rec709", "Rec709", "Rec709", "Limited"), "Raw": ("Raw", "Linear", "Null", "Full"),
}
"""Each named colour space's primaries, transfer function, Y'CbCr encoding and range (libcamera's)."""


def _member_enum(name: str, members: dict[str, int]) -> type[enum.IntEnum]:
    """An enum nested in ColorSpace, named so that pickle finds it (requests go to other processes)."""
    return enum.IntEnum(name, members, module=__name__, qualname=f"ColorSpace.{name}")


class ColorSpace:
    """A colour space: a name (``Sycc``, ``Smpte170m``, ``Rec709``, ``Raw``) and libcamera's four fields
    (``primaries``, ``transferFunction``, ``ycbcrEncoding``, ``range``); rollcam's ISP has one look."""

    Primaries = _member_enum("Primaries", {"Raw": 0, "Smpte170m": 1, "Rec709": 2, "Rec2020": 3})
    TransferFunction = _member_enum("TransferFunction", {"Linear": 0, "Srgb": 1, "Rec709": 2})
    YcbcrEncoding = _member_enum("YcbcrEncoding", {"Null": 0, "Rec601": 1, "Rec709": 2, "Rec2020": 3})
    Range = _member_enum("Range", {"Full": 0, "Limited": 1})

    def __init__(self, name: str | ColorSpace = "Sycc") -> None:
        self.name = name.name if isinstance(name, ColorSpace) else str(name)
        if isinstance(name, ColorSpace):
            fields = (name.primaries, name.transferFunction, name.ycbcrEncoding, name.range)
        else:
            p, t, y, r = _COLOUR_SPACE_FIELDS.get(self.name, _COLOUR_SPACE_FIELDS["Sycc"])
            fields = (self.Primaries[p], self.TransferFunction[t], self.YcbcrEncoding[y], self.Range[r])
        self.primaries, self.transferFunction, self.ycbcrEncoding, self.range = fields

    def _key(self) -> tuple[Any, ...]:
        return (self.primaries, self.transferFunction, self.ycbcrEncoding, self.range)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, ColorSpace) and other._key() == self._key()

    def __hash__(self) -> int:
        return hash(self._key())

    def __repr__(self) -> str:
        return f"<libcamera.ColorSpace '{self.name}'>"

    @classmethod
    def Sycc(cls) -> ColorSpace:
        return cls("Sycc")

    @classmethod
    def Smpte170m(cls) -> ColorSpace:
        return cls("Smpte170m")

    @classmethod
    def Rec709(cls) -> ColorSpace:
        return cls("Rec709")

    @classmethod
    def Raw(cls) -> ColorSpace:
        return cls("Raw")


def _enum(name: str, *members: str) -> type[enum.IntEnum]:
    return enum.IntEnum(name, {m: i for i, m in enumerate(members)})


_CONTROL_ENUMS: dict[str, Any] = {
    "AeMeteringModeEnum": _enum("AeMeteringModeEnum", "CentreWeighted", "Spot", "Matrix", "Custom"),
    "AeConstraintModeEnum": _enum("AeConstraintModeEnum", "Normal", "Highlight", "Shadows", "Custom"),
    "AeExposureModeEnum": _enum("AeExposureModeEnum", "Normal", "Short", "Long", "Custom"),
    "AwbModeEnum": _enum("AwbModeEnum", "Auto", "Incandescent", "Tungsten", "Fluorescent", "Indoor", "Daylight",
                         "Cloudy", "Custom"),
    "AfModeEnum": _enum("AfModeEnum", "Manual", "Auto", "Continuous"),
    "AfRangeEnum": _enum("AfRangeEnum", "Normal", "Macro", "Full"),
    "AfSpeedEnum": _enum("AfSpeedEnum", "Normal", "Fast"),
    "AfTriggerEnum": _enum("AfTriggerEnum", "Start", "Cancel"),
    "AfStateEnum": _enum("AfStateEnum", "Idle", "Scanning", "Focused", "Failed"),
    "AfPauseEnum": _enum("AfPauseEnum", "Immediate", "Deferred", "Resume"),
    "AfPauseStateEnum": _enum("AfPauseStateEnum", "Running", "Pausing", "Paused"),
    "AfMeteringEnum": _enum("AfMeteringEnum", "Auto", "Windows"),
    "ExposureTimeModeEnum": _enum("ExposureTimeModeEnum", "Auto", "Manual"),
    "AnalogueGainModeEnum": _enum("AnalogueGainModeEnum", "Auto", "Manual"),
    "HdrModeEnum": _enum("HdrModeEnum", "Off", "MultiExposureUnmerged", "MultiExposure", "SingleExposure",
                         "Night"),
}

controls = SimpleNamespace(**_CONTROL_ENUMS, draft=SimpleNamespace(
    NoiseReductionModeEnum=_enum("NoiseReductionModeEnum", "Off", "Fast", "HighQuality", "Minimal", "ZSL")))
"""libcamera's control enumerations, by libcamera's names (``controls.AfModeEnum.Continuous``, ...)."""
