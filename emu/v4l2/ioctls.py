"""The ioctl core of a device node: a program's ``ioctl(fd, VIDIOC_*, &arg)`` bytes in, the kernel's answer out.

``handle(node, file, request, data)`` does what Linux's v4l2-ioctl.c and the vb2 ioctl helpers do before and
after a driver: unknown requests get ENOTTY, the buffer type and memory are checked, priority and queue
ownership give EBUSY, and the driver reads and answers the program's structure itself (``raw``'s, one
declaration of each). Control changes are announced as events to the files that subscribed, those an injected
register reset made (``rollcam.firmware.labfaults``) at the next request any file makes.
"""

from __future__ import annotations

import ctypes as C
import errno
from collections.abc import Callable
from typing import Any

from . import abi, ctrls, raw
from .events import EVENT_CTRL
from .ioctls_buffers import BUFFER_HANDLERS
from .node import PRIO_BACKGROUND, PRIO_INTERACTIVE, PRIO_RECORD, READ_BUFFERS, Answer, DeviceNode, OpenFile
from .queue import V4L2Error

CAPTURE = raw.BufType.VIDEO_CAPTURE
PRIV_MAGIC = 0xFEEDCAFE
_PRIO_CHECKED = {"S_PRIORITY", "S_FMT", "S_CTRL", "S_EXT_CTRLS", "REQBUFS", "STREAMON", "STREAMOFF", "S_PARM",
                 "S_INPUT"}
_QUEUE_CHECKED = {"REQBUFS", "QBUF", "DQBUF", "STREAMON", "STREAMOFF", "EXPBUF"}
_CONTROL_CHANGERS = {"S_CTRL", "S_EXT_CTRLS", "S_FMT", "S_PARM", "STREAMON", "STREAMOFF", "S_INPUT"}


def handle(node: DeviceNode, f: OpenFile, request: int, data: bytes) -> Answer:
    """Run one ioctl; V4L2Error carries the errno (the ext-controls array still comes back on error)."""
    name, struct = abi.BY_NUMBER.get(request, (None, None))
    allowed = node.driver.requests
    if name not in HANDLERS or (allowed is not None and name not in allowed):
        raise V4L2Error(errno.ENOTTY, f"ioctl {name or hex(request)} is not supported by this device")
    arg: Any = None
    size = 0 if struct is None else C.sizeof(struct)
    if struct is not None:
        if len(data) < size:
            raise V4L2Error(errno.EFAULT, f"{name}: {len(data)} bytes for a {size}-byte argument")
        arg = struct.from_buffer_copy(data[:size])
    with node.lock:
        if node.driver.queue.disconnected and name not in ("QUERYCAP", "DQEVENT"):
            raise V4L2Error(errno.ENODEV, f"{name}: device disconnected")
        reset = node.driver.take_reset() if _has_controls(node) else None
        if reset is not None:  # an injected register reset changed the controls: subscribers hear of it now
            node.notify_controls(reset, None)
        if name in _PRIO_CHECKED:
            node.check_priority(f)
        if name in _QUEUE_CHECKED:
            node.check_owner(f)
            if node.fileio is not None:
                raise V4L2Error(errno.EBUSY, f"{name} while read() I/O owns the buffers")
        before = ctrls.controls(node.driver) if name in _CONTROL_CHANGERS and _has_controls(node) else None
        extra = data[size:]
        try:
            out = HANDLERS[name](node, f, arg, extra) if name in _WITH_EXTRA else HANDLERS[name](node, f, arg)
        finally:
            if before is not None:
                node.notify_controls(before, f)
            node.sync()
    if isinstance(out, Answer):
        return out
    if isinstance(out, raw.Struct):  # the driver's answer, whole: the kernel's structure, reserved fields zero
        return Answer(0, bytes(out))
    return Answer(int(out or 0), None if struct is None else bytes(arg))


def _type(node: DeviceNode, t: int) -> None:
    if t != node.driver.buf_type:
        raise V4L2Error(errno.EINVAL, f"buffer type {t} is not {node.driver.buf_type.name}")


def _has_controls(node: DeviceNode) -> bool:
    return node.driver.buf_type == CAPTURE  # a metadata node has none (its camera's are the image node's)


def _is_meta(node: DeviceNode) -> bool:
    return node.driver.buf_type == raw.BufType.META_CAPTURE


# ------------------------------------------------------------------------------------------- device and formats
def _querycap(node: DeviceNode, _f: OpenFile, _a: raw.Capability) -> raw.Capability:
    c = node.driver.ioctl(raw.Ioctl.QUERYCAP)
    c.bus_info = f"{c.bus_info}-{node.bus_minor}"
    rw = 0 if _is_meta(node) else raw.Cap.READWRITE  # vb2's read() emulation: on the image node only
    c.device_caps |= rw
    c.capabilities |= raw.Cap.READWRITE
    return c


def _enum_fmt(node: DeviceNode, _f: OpenFile, a: raw.FmtDesc) -> raw.FmtDesc:
    _type(node, a.type)
    return node.driver.ioctl(raw.Ioctl.ENUM_FMT, a)


def _put_pix(a: raw.Format, p: raw.PixFormat) -> None:
    C.memset(C.addressof(a.fmt), 0, C.sizeof(a.fmt))
    a.fmt.pix = p
    a.fmt.pix.priv = PRIV_MAGIC


def _put_meta(a: raw.Format) -> None:
    """The metadata node's one format, whatever was asked (as uvcvideo's meta node answers TRY/S_FMT)."""
    from .meta import BUFFER_SIZE, META_FOURCC

    C.memset(C.addressof(a.fmt), 0, C.sizeof(a.fmt))
    a.fmt.meta = raw.MetaFormat(META_FOURCC, BUFFER_SIZE)


def _g_fmt(node: DeviceNode, _f: OpenFile, a: raw.Format) -> None:
    _type(node, a.type)
    if _is_meta(node):
        return _put_meta(a)
    _put_pix(a, node.driver.fmt)


def _try_fmt(node: DeviceNode, _f: OpenFile, a: raw.Format) -> None:
    _type(node, a.type)
    if _is_meta(node):
        return _put_meta(a)
    _put_pix(a, node.driver.ioctl(raw.Ioctl.TRY_FMT, a.fmt.pix))


def _s_fmt(node: DeviceNode, f: OpenFile, a: raw.Format) -> None:
    _type(node, a.type)
    if _is_meta(node):
        if node.driver.queue.slots and node.owner is not f:
            raise V4L2Error(errno.EBUSY, "S_FMT while another file owns the buffers")
        return _put_meta(a)
    want = a.fmt.pix
    if node.driver.queue.slots and (node.owner is not f or node.driver.ioctl(raw.Ioctl.TRY_FMT, want) !=
                                    node.driver.fmt):
        raise V4L2Error(errno.EBUSY, "S_FMT while buffers are allocated")
    _put_pix(a, node.driver.fmt if node.driver.queue.slots else node.driver.ioctl(raw.Ioctl.S_FMT, want))


def _enum_framesizes(node: DeviceNode, _f: OpenFile, a: raw.FrmSizeEnum) -> raw.FrmSizeEnum:
    return node.driver.ioctl(raw.Ioctl.ENUM_FRAMESIZES, a)


def _enum_frameintervals(node: DeviceNode, _f: OpenFile, a: raw.FrmIvalEnum) -> raw.FrmIvalEnum:
    """The mode's frame interval, DISCRETE (S_PARM still takes any interval: it sets the frame length)."""
    return node.driver.ioctl(raw.Ioctl.ENUM_FRAMEINTERVALS, a)


def _parm(a: raw.StreamParm, p: raw.StreamParm) -> None:
    a.parm = p.parm
    a.parm.capture.readbuffers = READ_BUFFERS


def _g_parm(node: DeviceNode, _f: OpenFile, a: raw.StreamParm) -> None:
    _type(node, a.type)
    _parm(a, node.driver.ioctl(raw.Ioctl.G_PARM))


def _s_parm(node: DeviceNode, _f: OpenFile, a: raw.StreamParm) -> None:
    _type(node, a.type)
    _parm(a, node.driver.ioctl(raw.Ioctl.S_PARM, a))


def _enuminput(node: DeviceNode, _f: OpenFile, a: raw.Input) -> raw.Input:
    return node.driver.ioctl(raw.Ioctl.ENUMINPUT, a)


def _g_input(node: DeviceNode, _f: OpenFile, a: C.c_int) -> None:
    a.value = node.driver.ioctl(raw.Ioctl.G_INPUT)


def _s_input(node: DeviceNode, _f: OpenFile, a: C.c_int) -> None:
    a.value = node.driver.ioctl(raw.Ioctl.S_INPUT, a.value)


def _g_priority(node: DeviceNode, _f: OpenFile, a: C.c_uint32) -> None:
    a.value = max((g.priority for g in node.files), default=PRIO_INTERACTIVE)  # v4l2_prio_max


def _s_priority(_node: DeviceNode, f: OpenFile, a: C.c_uint32) -> None:
    if not PRIO_BACKGROUND <= a.value <= PRIO_RECORD:
        raise V4L2Error(errno.EINVAL, f"priority {a.value} is not 1..3")
    f.priority = a.value


def _log_status(node: DeviceNode, _f: OpenFile, _a: None) -> None:
    return None


# ------------------------------------------------------------------------------------------------- controls
def _queryctrl(node: DeviceNode, _f: OpenFile, a: raw.QueryCtrl) -> raw.QueryCtrl:
    c = ctrls.find(node.driver, a.id)
    q = raw.QueryCtrl(c.id, c.type, c.name, flags=c.flags)
    if c.type in (raw.CtrlType.INTEGER, raw.CtrlType.BOOLEAN, raw.CtrlType.MENU):
        q.minimum, q.maximum, q.step, q.default_value = c.minimum, c.maximum, c.step, c.default
    return q


def _query_ext_ctrl(node: DeviceNode, _f: OpenFile, a: raw.QueryExtCtrl) -> raw.QueryExtCtrl:
    return node.driver.ioctl(raw.Ioctl.QUERY_EXT_CTRL, a)


def _querymenu(node: DeviceNode, _f: OpenFile, a: raw.QueryMenu) -> None:
    a.name = node.driver.ioctl(raw.Ioctl.QUERYMENU, a).name
    a.reserved = 0


def _g_ctrl(node: DeviceNode, _f: OpenFile, a: raw.Control) -> None:
    node.driver.admit(raw.Ioctl.G_CTRL)  # unplugged, or an injected error: as the driver's own ioctl
    a.value = ctrls.KERNEL_CTRL[raw.Ioctl.G_CTRL](node.driver, a).value


def _s_ctrl(node: DeviceNode, _f: OpenFile, a: raw.Control) -> None:
    node.driver.admit(raw.Ioctl.S_CTRL)
    a.value = ctrls.KERNEL_CTRL[raw.Ioctl.S_CTRL](node.driver, a).value


def _ext_ctrls(request: raw.Ioctl) -> Callable[..., Answer]:
    def run(node: DeviceNode, _f: OpenFile, a: raw.ExtControls, extra: bytes) -> Answer:
        n = a.count
        if n > 1024:
            raise V4L2Error(errno.EINVAL, f"{n} controls in one call (at most 1024)")
        if n and len(extra) < n * C.sizeof(raw.ExtControl):
            raise V4L2Error(errno.EFAULT, "the controls array is not readable")
        items = (raw.ExtControl * n).from_buffer_copy(extra[: n * C.sizeof(raw.ExtControl)])
        program_array, a.controls, a.error_idx = a.controls, C.addressof(items), 0  # the driver works on our copy
        try:
            node.driver.ioctl(request, a)
            err = None
        except V4L2Error as exc:
            err = exc
        a.controls = program_array
        for c in items:
            c.size = 0
        data = bytes(a) + bytes(items)
        if err is not None:
            raise _WithData(err, data)
        return Answer(0, data)

    return run


class _WithData(V4L2Error):
    """An error whose argument still goes back (the kernel copies ext-controls back on failure)."""

    def __init__(self, err: V4L2Error, data: bytes) -> None:
        super().__init__(err.errno, str(err))
        self.data = data


def _subscribe(node: DeviceNode, f: OpenFile, a: raw.EventSubscription) -> None:
    ctrl = ctrls.controls(node.driver).get(a.id) if a.type == EVENT_CTRL else None
    f.events.subscribe(a.type, a.id, a.flags, ctrl)


def _unsubscribe(_node: DeviceNode, f: OpenFile, a: raw.EventSubscription) -> None:
    f.events.unsubscribe(a.type, a.id)


def _dqevent(node: DeviceNode, f: OpenFile, a: raw.Event) -> None:
    if node.driver.queue.disconnected:
        raise V4L2Error(errno.ENODEV, "device disconnected")
    ev, left = f.events.dequeue()
    C.memset(C.addressof(a), 0, C.sizeof(a))
    a.type, a.id, a.pending, a.sequence = EVENT_CTRL, ev.id, left, ev.sequence
    a.timestamp.tv_sec, a.timestamp.tv_nsec = divmod(ev.timestamp_ns, 1_000_000_000)
    c = ev.ctrl
    e = a.u.ctrl
    e.changes, e.type, e.value64, e.flags = ev.changes, c.type, c.value, c.flags
    if c.type != raw.CtrlType.INTEGER64:
        e.minimum, e.maximum, e.step, e.default_value = c.minimum, c.maximum, c.step, c.default


HANDLERS: dict[str, Callable[..., Any]] = {
    "QUERYCAP": _querycap, "ENUM_FMT": _enum_fmt, "G_FMT": _g_fmt, "S_FMT": _s_fmt, "TRY_FMT": _try_fmt,
    "ENUM_FRAMESIZES": _enum_framesizes, "ENUM_FRAMEINTERVALS": _enum_frameintervals, "G_PARM": _g_parm,
    "S_PARM": _s_parm, "ENUMINPUT": _enuminput, "G_INPUT": _g_input, "S_INPUT": _s_input,
    "G_PRIORITY": _g_priority, "S_PRIORITY": _s_priority, "LOG_STATUS": _log_status,
    "QUERYCTRL": _queryctrl, "QUERY_EXT_CTRL": _query_ext_ctrl, "QUERYMENU": _querymenu, "G_CTRL": _g_ctrl,
    "S_CTRL": _s_ctrl, "G_EXT_CTRLS": _ext_ctrls(raw.Ioctl.G_EXT_CTRLS),
    "S_EXT_CTRLS": _ext_ctrls(raw.Ioctl.S_EXT_CTRLS), "TRY_EXT_CTRLS": _ext_ctrls(raw.Ioctl.TRY_EXT_CTRLS),
    "SUBSCRIBE_EVENT": _subscribe, "UNSUBSCRIBE_EVENT": _unsubscribe, "DQEVENT": _dqevent,
    **BUFFER_HANDLERS,
}
_WITH_EXTRA = {"G_EXT_CTRLS", "S_EXT_CTRLS", "TRY_EXT_CTRLS"}
