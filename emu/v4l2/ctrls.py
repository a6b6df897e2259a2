"""The driver's controls as the V4L2 control framework presents them: types, classes, extended controls.

Linux sensor drivers register their controls with v4l2-ctrls, which adds the class controls, 64-bit types
(PIXEL_RATE is INTEGER64), ``V4L2_CTRL_FLAG_NEXT_CTRL`` enumeration, ``VIDIOC_QUERY_EXT_CTRL`` and the
``G/S/TRY_EXT_CTRLS`` rules (``which``, ``error_idx``, clamping, ERANGE for a bad menu index). These handlers
give the emulated driver the same on top of ``rollcam.firmware.controls``, plus two read-only controls of
rollcam's: the rolling-shutter line time (ns) and the readout direction.
"""

from __future__ import annotations

import ctypes as C
import errno
from dataclasses import dataclass
from typing import Any

from rollcam.common.errors import ConfigError, DeviceError
from rollcam.sim.timing import Readout

from . import raw
from .queue import V4L2Error

CID_TO_CONTROL = {raw.CID.EXPOSURE: "exposure", raw.CID.ANALOGUE_GAIN: "analogue_gain",
                  raw.CID.DIGITAL_GAIN: "digital_gain", raw.CID.VBLANK: "vblank", raw.CID.HBLANK: "hblank",
                  raw.CID.PIXEL_RATE: "pixel_rate", raw.CID.TEST_PATTERN: "test_pattern", raw.CID.HFLIP: "hflip",
                  raw.CID.VFLIP: "vflip"}
"""The V4L2 control IDs of the sensor controls (``rollcam.firmware.controls`` names), as Linux sensor drivers
register them."""

_T = raw.CtrlType
_F = raw.CtrlFlag
_NEXT = int(_F.NEXT_CTRL | _F.NEXT_COMPOUND)
MODIFY_LAYOUT = 0x0400  # V4L2_CTRL_FLAG_MODIFY_LAYOUT: a flip changes the Bayer order of raw formats
READOUTS = [r.value for r in Readout]
CLASS_NAMES = {raw.CID.USER_CLASS: "User Controls", raw.CID.CAMERA_CLASS: "Camera Controls",
               raw.CID.IMAGE_SOURCE_CLASS: "Image Source Controls",
               raw.CID.IMAGE_PROC_CLASS: "Image Processing Controls"}
MAX_LINE_TIME_NS = 1_000_000_000
EXPOSURE_UNIT_NS = 100_000  # V4L2_CID_EXPOSURE_ABSOLUTE counts 100 us
V4L2_NAMES = {"exposure": "Exposure", "analogue_gain": "Analogue Gain", "digital_gain": "Digital Gain",
              "vblank": "Vertical Blanking", "hblank": "Horizontal Blanking", "pixel_rate": "Pixel Rate",
              "test_pattern": "Test Pattern", "hflip": "Horizontal Flip", "vflip": "Vertical Flip"}
_KINDS = {"int": _T.INTEGER, "bool": _T.BOOLEAN, "menu": _T.MENU}


@dataclass(frozen=True)
class Ctrl:
    """One control as QUERY_EXT_CTRL describes it, and its current value (``items``: a menu's names)."""

    id: int
    type: int
    name: str
    minimum: int
    maximum: int
    step: int
    default: int
    flags: int
    value: int
    items: tuple[str, ...] = ()


def _control_names() -> dict[int, str]:
    return {int(cid): name for cid, name in CID_TO_CONTROL.items()}


def controls(d: Any) -> dict[int, Ctrl]:
    """Every control of driver ``d`` by id, in id order (the order NEXT_CTRL enumerates)."""
    cam = d.camera
    info = cam.controls()
    defaults = d.ctrl_defaults
    out: dict[int, Ctrl] = {int(cid): Ctrl(int(cid), _T.CTRL_CLASS, name, 0, 0, 0, 0,
                                           int(_F.READ_ONLY | _F.WRITE_ONLY), 0)
                            for cid, name in CLASS_NAMES.items()}
    for cid, name in _control_names().items():
        if name in ("hflip", "vflip") and getattr(cam.traits, f"{name}_bit", None) is None:
            continue  # the sensor cannot flip: its driver registers no flip control
        i = info[name]
        kind = _T.INTEGER64 if name == "pixel_rate" else _KINDS[i["kind"]]
        flags = int(_F.READ_ONLY) if i["read_only"] else 0
        if name in ("hflip", "vflip"):
            flags |= MODIFY_LAYOUT | (int(_F.GRABBED) if cam.streaming else 0)
        default = min(max(defaults.get(name, i["value"]), i["min"]), i["max"])
        out[cid] = Ctrl(cid, kind, V4L2_NAMES[name], i["min"], i["max"], 1, default, flags, i["value"],
                        tuple(i["menu"] or ()))
    s = cam.spec.settings
    # EXPOSURE_ABSOLUTE (what UVC cameras and OpenCV's CAP_PROP_EXPOSURE use): the exposure in 100 us units.
    row_ns = max(int(s.timing.line_time_ns), 1)
    e = out[int(raw.CID.EXPOSURE)]
    lo, hi = -(-e.minimum * row_ns // EXPOSURE_UNIT_NS), max(e.maximum * row_ns // EXPOSURE_UNIT_NS, 1)
    out[int(raw.CID.EXPOSURE_ABSOLUTE)] = Ctrl(
        int(raw.CID.EXPOSURE_ABSOLUTE), _T.INTEGER, "Exposure Time, Absolute", lo, max(hi, lo), 1,
        min(max(e.default * row_ns // EXPOSURE_UNIT_NS, lo), max(hi, lo)), 0,
        min(max(round(e.value * row_ns / EXPOSURE_UNIT_NS), lo), max(hi, lo)))
    line_ns = 0 if s.shutter == "global" else int(s.timing.line_time_ns)
    out[int(raw.CID.ROLLCAM_LINE_TIME)] = Ctrl(int(raw.CID.ROLLCAM_LINE_TIME), _T.INTEGER64, "Line Time (ns)",
                                               0, MAX_LINE_TIME_NS, 1, line_ns, int(_F.READ_ONLY), line_ns)
    readout = READOUTS.index(s.readout.value)
    out[int(raw.CID.ROLLCAM_READOUT)] = Ctrl(int(raw.CID.ROLLCAM_READOUT), _T.MENU, "Readout Direction", 0,
                                             len(READOUTS) - 1, 1, readout, int(_F.READ_ONLY), readout,
                                             tuple(READOUTS))
    return dict(sorted(out.items()))


def find(d: Any, cid: int) -> Ctrl:
    """The control ``cid`` (NEXT_CTRL: the first one after it); EINVAL if there is none."""
    table = controls(d)
    if cid & _NEXT == _F.NEXT_COMPOUND:
        raise V4L2Error(errno.EINVAL, "no compound controls")
    if cid & _NEXT:
        base = cid & ~_NEXT
        for k, c in table.items():
            if k > base:
                return c
        raise V4L2Error(errno.EINVAL, f"no control after {base:#x}")
    try:
        return table[cid]
    except KeyError:
        raise V4L2Error(errno.EINVAL, f"no control with id {cid:#x}") from None


def _query_ext(d: Any, arg: raw.QueryExtCtrl) -> raw.QueryExtCtrl:
    c = find(d, arg.id)
    size = 8 if c.type == _T.INTEGER64 else 0 if c.type == _T.CTRL_CLASS else 4
    return raw.QueryExtCtrl(c.id, c.type, c.name, c.minimum, c.maximum, c.step, c.default, c.flags, size, 1)


def _querymenu(d: Any, arg: raw.QueryMenu) -> raw.QueryMenu:
    c = find(d, arg.id & ~_NEXT)
    if c.type != _T.MENU or not 0 <= arg.index < len(c.items):
        raise V4L2Error(errno.EINVAL, f"no menu item {arg.index} for control {arg.id:#x}")
    return raw.QueryMenu(c.id, arg.index, c.items[arg.index])


def _validate(c: Ctrl, value: int) -> int:
    """The value the framework would store (validate_new): integers clamped, booleans 0/1, menus checked."""
    if c.flags & _F.READ_ONLY:
        raise V4L2Error(errno.EACCES, f"control {c.name!r} is read-only")
    if c.type == _T.BOOLEAN:
        return int(bool(value))
    if c.type == _T.MENU:
        if not c.minimum <= value <= c.maximum:
            raise V4L2Error(errno.ERANGE, f"menu index {value} of {c.name!r} is not in {c.minimum}..{c.maximum}")
        return value
    return min(max(value, c.minimum), c.maximum)


def _store(d: Any, c: Ctrl, value: int) -> int:
    if c.id == raw.CID.EXPOSURE_ABSOLUTE:
        row_ns = max(int(d.camera.spec.settings.timing.line_time_ns), 1)
        d.camera.set_control("exposure", max(round(value * EXPOSURE_UNIT_NS / row_ns), 1))
        return controls(d)[c.id].value
    name = _control_names()[c.id]
    try:
        return d.camera.set_control(name, value)
    except DeviceError as exc:  # a flip while streaming: the control is grabbed
        raise V4L2Error(errno.EBUSY, f"{c.name}: {exc}") from None
    except ConfigError as exc:
        raise V4L2Error(errno.EINVAL, f"{c.name}: {exc}") from None


def _g_ctrl(d: Any, arg: raw.Control) -> raw.Control:
    c = find(d, arg.id & ~_NEXT)
    if c.type in (_T.INTEGER64, _T.CTRL_CLASS):
        raise V4L2Error(errno.EINVAL, f"control {c.name!r} needs VIDIOC_G_EXT_CTRLS")
    return raw.Control(c.id, c.value)


def _s_ctrl(d: Any, arg: raw.Control) -> raw.Control:
    c = find(d, arg.id & ~_NEXT)
    if c.type in (_T.INTEGER64, _T.CTRL_CLASS):
        raise V4L2Error(errno.EACCES if c.flags & _F.READ_ONLY else errno.EINVAL,
                        f"control {c.name!r} needs VIDIOC_S_EXT_CTRLS")
    return raw.Control(c.id, _store(d, c, _validate(c, int(arg.value))))


def _value(c: Ctrl | None, item: raw.ExtControl) -> int:
    """An item's value: ``value64``, or for a 32-bit control its low half, signed."""
    return item.value64 if c is not None and c.type == _T.INTEGER64 else C.c_int32(item.value64 & 0xFFFFFFFF).value


def _put(c: Ctrl, item: raw.ExtControl, value: int) -> None:
    """Write ``value`` back as the framework does: a 32-bit control's into the low half only."""
    item.value64 = value if c.type == _T.INTEGER64 else (item.value64 & ~0xFFFFFFFF) | (value & 0xFFFFFFFF)


def _ext(d: Any, arg: raw.ExtControls, mode: str) -> raw.ExtControls:
    """G/TRY/S_EXT_CTRLS on ``arg``'s array, in place (values written back on success). ``error_idx``: the
    failing index for TRY, ``count`` for G and S (nothing was set)."""
    items = raw.ext_controls(arg)
    count = arg.count
    which = arg.which
    fail_idx = lambda i: i if mode == "try" else count  # noqa: E731

    def error(err: int, i: int, message: str) -> V4L2Error:
        arg.error_idx = fail_idx(i)
        return V4L2Error(err, message)

    class_ok = which in (raw.CtrlWhich.CUR_VAL, raw.CtrlWhich.DEF_VAL) or (which | 1) in CLASS_NAMES
    if not class_ok or (which == raw.CtrlWhich.DEF_VAL and mode != "get"):
        raise error(errno.EINVAL, 0 if mode == "try" else count, f"which {which:#x} is not valid here")
    table = controls(d)
    found: list[Ctrl] = []
    for i, item in enumerate(items):
        cid = item.id
        c = table.get(cid)
        if c is None:
            raise error(errno.EINVAL, i, f"no control with id {cid:#x}")
        if mode == "get" and c.flags & _F.WRITE_ONLY:
            raise error(errno.EACCES, i, f"control {c.name!r} is write-only")
        if which not in (raw.CtrlWhich.CUR_VAL, raw.CtrlWhich.DEF_VAL) and (cid & 0x0FFF0000) != which:
            raise error(errno.EINVAL, i, f"control {cid:#x} is not in class {which:#x}")
        found.append(c)
    if mode == "get":
        for c, item in zip(found, items, strict=True):
            _put(c, item, c.default if which == raw.CtrlWhich.DEF_VAL else c.value)
        arg.error_idx = 0
        return arg
    values = []
    for i, (c, item) in enumerate(zip(found, items, strict=True)):
        try:
            values.append(_validate(c, _value(c, item)))
        except V4L2Error as exc:
            raise error(exc.errno, i, str(exc)) from None
        if mode == "set" and c.flags & _F.GRABBED:
            raise error(errno.EBUSY, i, f"control {c.name!r} is grabbed while streaming")
    if mode == "set":
        values = [_store(d, c, v) for c, v in zip(found, values, strict=True)]
    for c, item, v in zip(found, items, values, strict=True):
        _put(c, item, v)
    arg.error_idx = 0 if mode == "try" else count
    return arg


def _enuminput(_d: Any, arg: raw.Input) -> raw.Input:
    if arg.index != 0:
        raise V4L2Error(errno.EINVAL, f"input {arg.index} does not exist (one input: 0)")
    return raw.Input(0, "Camera", raw.INPUT_TYPE_CAMERA)


def _s_input(_d: Any, arg: int) -> int:
    if int(arg) != 0:
        raise V4L2Error(errno.EINVAL, f"input {arg} does not exist (one input: 0)")
    return 0


HANDLERS = {
    raw.Ioctl.QUERY_EXT_CTRL: _query_ext, raw.Ioctl.QUERYMENU: _querymenu,
    raw.Ioctl.G_EXT_CTRLS: lambda d, a: _ext(d, a, "get"), raw.Ioctl.TRY_EXT_CTRLS: lambda d, a: _ext(d, a, "try"),
    raw.Ioctl.S_EXT_CTRLS: lambda d, a: _ext(d, a, "set"),
    raw.Ioctl.ENUMINPUT: _enuminput, raw.Ioctl.G_INPUT: lambda _d, _a: 0, raw.Ioctl.S_INPUT: _s_input,
}
"""The control-framework requests, added to the driver's handler table. Node-level G/S_CTRL go through
``KERNEL_CTRL``: they refuse 64-bit and class controls as the framework does."""

KERNEL_CTRL = {raw.Ioctl.G_CTRL: _g_ctrl, raw.Ioctl.S_CTRL: _s_ctrl}
"""G/S_CTRL with the framework's types (the driver's own keep their in-process behaviour)."""
