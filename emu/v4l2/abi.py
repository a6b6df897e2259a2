"""The ``VIDIOC_*`` request numbers (LP64 Linux) and the structure each one carries.

What a program hands ``ioctl(fd, VIDIOC_..., &arg)`` arrives at the device node (``rollcam.emu.v4l2.node``) as
the bytes of ``arg``; the structures that read and write them are ``raw``'s (their one home), named here too.
"""

from __future__ import annotations

import ctypes as C

from . import raw
from .raw import (  # the structures, also by this module's name (what programs that call ioctl import)
    Buffer,
    Capability,
    Control,
    Event,
    EventSubscription,
    ExportBuffer,
    ExtControls,
    FmtDesc,
    Format,
    FrmIvalEnum,
    FrmSizeEnum,
    Input,
    QueryCtrl,
    QueryExtCtrl,
    QueryMenu,
    RequestBuffers,
    Selection,
    StreamParm,
)

__all__ = ["BY_NUMBER", "REQUESTS", "Buffer", "Capability", "Control", "Event", "EventSubscription", "ExportBuffer",
           "ExtControls", "FmtDesc", "Format", "FrmIvalEnum", "FrmSizeEnum", "Input", "QueryCtrl", "QueryExtCtrl",
           "QueryMenu", "RequestBuffers", "Selection", "StreamParm"]


# -------------------------------------------------------------------------------------------- request numbers
_IOC_WRITE, _IOC_READ = 1, 2


def _ioc(direction: int, nr: int, struct: type | None) -> int:
    size = 0 if struct is None else C.sizeof(struct)
    return (direction << 30) | (size << 16) | (ord("V") << 8) | nr


def _request(direction: int, nr: int, struct: type | None) -> tuple[int, type | None]:
    return _ioc(direction, nr, struct), struct


_R, _W, _RW = _IOC_READ, _IOC_WRITE, _IOC_READ | _IOC_WRITE

REQUESTS: dict[str, tuple[int, type | None]] = {
    "QUERYCAP": _request(_R, 0, raw.Capability),
    "ENUM_FMT": _request(_RW, 2, raw.FmtDesc),
    "G_FMT": _request(_RW, 4, raw.Format),
    "S_FMT": _request(_RW, 5, raw.Format),
    "REQBUFS": _request(_RW, 8, raw.RequestBuffers),
    "QUERYBUF": _request(_RW, 9, raw.Buffer),
    "QBUF": _request(_RW, 15, raw.Buffer),
    "EXPBUF": _request(_RW, 16, raw.ExportBuffer),
    "DQBUF": _request(_RW, 17, raw.Buffer),
    "STREAMON": _request(_W, 18, C.c_int),
    "STREAMOFF": _request(_W, 19, C.c_int),
    "G_PARM": _request(_RW, 21, raw.StreamParm),
    "S_PARM": _request(_RW, 22, raw.StreamParm),
    "G_STD": _request(_R, 23, C.c_uint64),
    "S_STD": _request(_W, 24, C.c_uint64),
    "ENUMINPUT": _request(_RW, 26, raw.Input),
    "G_CTRL": _request(_RW, 27, raw.Control),
    "S_CTRL": _request(_RW, 28, raw.Control),
    "QUERYCTRL": _request(_RW, 36, raw.QueryCtrl),
    "QUERYMENU": _request(_RW, 37, raw.QueryMenu),
    "G_INPUT": _request(_R, 38, C.c_int),
    "S_INPUT": _request(_RW, 39, C.c_int),
    "TRY_FMT": _request(_RW, 64, raw.Format),
    "G_PRIORITY": _request(_R, 67, C.c_uint32),
    "S_PRIORITY": _request(_W, 68, C.c_uint32),
    "LOG_STATUS": _request(0, 70, None),
    "G_EXT_CTRLS": _request(_RW, 71, raw.ExtControls),
    "S_EXT_CTRLS": _request(_RW, 72, raw.ExtControls),
    "TRY_EXT_CTRLS": _request(_RW, 73, raw.ExtControls),
    "ENUM_FRAMESIZES": _request(_RW, 74, raw.FrmSizeEnum),
    "ENUM_FRAMEINTERVALS": _request(_RW, 75, raw.FrmIvalEnum),
    "DQEVENT": _request(_R, 89, raw.Event),
    "SUBSCRIBE_EVENT": _request(_W, 90, raw.EventSubscription),
    "UNSUBSCRIBE_EVENT": _request(_W, 91, raw.EventSubscription),
    "G_SELECTION": _request(_RW, 94, raw.Selection),
    "QUERY_EXT_CTRL": _request(_RW, 103, raw.QueryExtCtrl),
}
"""Request name -> (number, argument structure)."""

BY_NUMBER: dict[int, tuple[str, type | None]] = {num: (name, st) for name, (num, st) in REQUESTS.items()}
"""Request number -> (name, argument structure)."""
