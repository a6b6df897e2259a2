"""Plain V4L2 functions acting on a handle (anything with ``ioctl(request, arg)``), as linuxpy's layer two.

Each builds the request's structure, makes the call and returns the kernel's answer; errors are the
driver's ``V4L2Error`` (an OSError with the kernel's errno, and a rollcam DeviceError).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace
from typing import Any, Protocol

import numpy as np

from . import raw
from .queue import BufferState, V4L2Error


class Handle(Protocol):
    """What the functions act on: the emulated driver, or a test double."""

    def ioctl(self, request: raw.Ioctl | str, arg: Any = None) -> Any:
        """One VIDIOC request."""


def querycap(h: Handle) -> raw.Capability:
    """VIDIOC_QUERYCAP."""
    return h.ioctl(raw.Ioctl.QUERYCAP)


def _enumerate(h: Handle, request: raw.Ioctl, make: Any) -> Iterator[Any]:
    index = 0
    while True:
        try:
            yield h.ioctl(request, make(index))
        except V4L2Error as exc:
            if exc.errno == 22:  # EINVAL ends an enumeration, as in the kernel
                return
            raise
        index += 1


def enum_formats(h: Handle) -> list[raw.FmtDesc]:
    """Every VIDIOC_ENUM_FMT entry."""
    return list(_enumerate(h, raw.Ioctl.ENUM_FMT, raw.FmtDesc))


def enum_frame_sizes(h: Handle, fourcc: str) -> list[raw.FrmSize]:
    """Every VIDIOC_ENUM_FRAMESIZES entry of a format."""
    return list(_enumerate(h, raw.Ioctl.ENUM_FRAMESIZES, lambda i: raw.FrmSize(i, fourcc)))


def enum_frame_intervals(h: Handle, fourcc: str, width: int, height: int) -> list[raw.FrmIval]:
    """Every VIDIOC_ENUM_FRAMEINTERVALS entry of a format and size."""
    return list(_enumerate(h, raw.Ioctl.ENUM_FRAMEINTERVALS, lambda i: raw.FrmIval(i, fourcc, width, height)))


def get_format(h: Handle) -> raw.PixFormat:
    """VIDIOC_G_FMT."""
    return h.ioctl(raw.Ioctl.G_FMT)


def try_format(h: Handle, width: int, height: int, fourcc: str) -> raw.PixFormat:
    """VIDIOC_TRY_FMT: what S_FMT would set (rounded to a supported size and format)."""
    return h.ioctl(raw.Ioctl.TRY_FMT, raw.PixFormat(width, height, fourcc))


def set_format(h: Handle, width: int, height: int, fourcc: str) -> raw.PixFormat:
    """VIDIOC_S_FMT; returns the format actually set."""
    return h.ioctl(raw.Ioctl.S_FMT, raw.PixFormat(width, height, fourcc))


def get_frame_interval(h: Handle) -> tuple[int, int]:
    """VIDIOC_G_PARM: time per frame as (numerator, denominator) seconds."""
    t = h.ioctl(raw.Ioctl.G_PARM).parm.capture.timeperframe
    return t.numerator, t.denominator


def set_frame_interval(h: Handle, numerator: int, denominator: int) -> tuple[int, int]:
    """VIDIOC_S_PARM; returns the interval actually set."""
    t = h.ioctl(raw.Ioctl.S_PARM, raw.stream_parm(numerator, denominator)).parm.capture.timeperframe
    return t.numerator, t.denominator


def query_control(h: Handle, cid: int) -> raw.QueryCtrl:
    """VIDIOC_QUERYCTRL."""
    return h.ioctl(raw.Ioctl.QUERYCTRL, raw.QueryCtrl(int(cid)))


def query_menu(h: Handle, cid: int, index: int) -> raw.QueryMenu:
    """VIDIOC_QUERYMENU."""
    return h.ioctl(raw.Ioctl.QUERYMENU, raw.QueryMenu(int(cid), index))


def get_control(h: Handle, cid: int) -> int:
    """VIDIOC_G_CTRL."""
    return h.ioctl(raw.Ioctl.G_CTRL, raw.Control(int(cid))).value


def set_control(h: Handle, cid: int, value: int) -> int:
    """VIDIOC_S_CTRL; returns the value in effect (integers are clamped to range)."""
    return h.ioctl(raw.Ioctl.S_CTRL, raw.Control(int(cid), int(value))).value


def request_buffers(h: Handle, count: int, memory: int = raw.Memory.MMAP) -> int:
    """VIDIOC_REQBUFS; returns the number allocated (0 frees them)."""
    return h.ioctl(raw.Ioctl.REQBUFS, raw.RequestBuffers(count, raw.BufType.VIDEO_CAPTURE, memory)).count


def query_buffer(h: Handle, index: int) -> BufferState:
    """VIDIOC_QUERYBUF: the buffer's state (timestamp in integer ns)."""
    return h.ioctl(raw.Ioctl.QUERYBUF, raw.Buffer(index))


def queue_buffer(h: Handle, index: int) -> BufferState:
    """VIDIOC_QBUF."""
    return h.ioctl(raw.Ioctl.QBUF, raw.Buffer(index))


def dequeue_buffer(h: Handle, *, block: bool = True, timeout_s: float | None = None
                   ) -> tuple[BufferState, np.ndarray]:
    """VIDIOC_DQBUF: the buffer's state (a copy) and a view of its first ``bytesused`` bytes (valid until
    re-queued)."""
    slot = h.ioctl(raw.Ioctl.DQBUF, {"block": block, "timeout_s": timeout_s})
    info = replace(slot.info, flags=int(slot.info.flags))
    return info, slot.memory[: info.bytesused]


def stream_on(h: Handle) -> None:
    """VIDIOC_STREAMON."""
    h.ioctl(raw.Ioctl.STREAMON, raw.BufType.VIDEO_CAPTURE)


def stream_off(h: Handle) -> None:
    """VIDIOC_STREAMOFF."""
    h.ioctl(raw.Ioctl.STREAMOFF, raw.BufType.VIDEO_CAPTURE)
