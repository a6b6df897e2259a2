"""The buffer requests of the ioctl core (vb2's ioctl helpers): REQBUFS, QUERYBUF, QBUF, DQBUF, EXPBUF,
STREAMON and STREAMOFF, with memory and type checks, queue ownership and the ``m.offset`` of shared buffers."""

from __future__ import annotations

import ctypes as C
import errno
import os
from typing import Any

from . import raw
from .node import Answer, DeviceNode, OpenFile
from .queue import BufferState, V4L2Error

BUF_CAP_SUPPORTS_MMAP = 1
BUF_CAP_SUPPORTS_ORPHANED_BUFS = 1 << 4  # REQBUFS 0 while mapped: the program's mappings stay valid (memfds)
FLAG_REQUEST_FD = 0x00800000
_STATE_FLAGS = raw.BufFlag.QUEUED | raw.BufFlag.DONE | raw.BufFlag.ERROR
_TIMESTAMP_FLAGS = raw.BufFlag.TIMESTAMP_MONOTONIC | raw.BufFlag.TSTAMP_SRC_SOE


def _check(node: DeviceNode, t: int, memory: int | None = None) -> None:
    if t != node.driver.buf_type:
        raise V4L2Error(errno.EINVAL, f"buffer type {t} is not {node.driver.buf_type.name}")
    if memory is not None and memory != raw.Memory.MMAP:
        raise V4L2Error(errno.EINVAL, f"memory {memory} is not MMAP (the only memory this device has)")


def fill(node: DeviceNode, info: BufferState) -> raw.Buffer:
    """``struct v4l2_buffer`` of a buffer's state (as vb2's ``__fill_v4l2_buffer``)."""
    flags = (info.flags & _STATE_FLAGS) | _TIMESTAMP_FLAGS
    if info.index in node.mapped:
        flags |= raw.BufFlag.MAPPED
    a = raw.Buffer(info.index, node.driver.buf_type, info.bytesused, int(flags), raw.Field.NONE,
                   sequence=info.sequence, memory=raw.Memory.MMAP, length=info.length)
    a.timestamp_ns = info.timestamp_ns
    a.m.offset = node.offset(info.index)
    return a


def _reqbufs(node: DeviceNode, f: OpenFile, a: raw.RequestBuffers) -> raw.RequestBuffers:
    _check(node, a.type)
    if a.memory != raw.Memory.MMAP:
        raise V4L2Error(errno.EINVAL, f"memory {a.memory} is not supported (MMAP only)")
    d = node.driver
    if d.queue.streaming:
        raise V4L2Error(errno.EBUSY, "REQBUFS while streaming")
    r = d.ioctl(raw.Ioctl.REQBUFS, a)
    node.reallocated()
    node.owner = f if r.count else None
    node.waiting_for_buffers = True
    r.capabilities = BUF_CAP_SUPPORTS_MMAP | BUF_CAP_SUPPORTS_ORPHANED_BUFS
    return r


def _querybuf(node: DeviceNode, _f: OpenFile, a: raw.Buffer) -> raw.Buffer:
    _check(node, a.type)
    return fill(node, node.driver.ioctl(raw.Ioctl.QUERYBUF, a))


def _qbuf(node: DeviceNode, _f: OpenFile, a: raw.Buffer) -> raw.Buffer:
    _check(node, a.type, a.memory)
    if a.flags & FLAG_REQUEST_FD:
        raise V4L2Error(errno.EBADR, "this device has no requests (media request API)")
    out = fill(node, node.driver.ioctl(raw.Ioctl.QBUF, a))
    node.waiting_for_buffers = False
    return out


def _dqbuf(node: DeviceNode, _f: OpenFile, a: raw.Buffer) -> raw.Buffer:
    _check(node, a.type, a.memory)
    slot = node.driver.ioctl(raw.Ioctl.DQBUF, {"block": False})
    return fill(node, slot.info)


def _expbuf(node: DeviceNode, _f: OpenFile, a: raw.ExportBuffer) -> Any:
    _check(node, a.type)
    if a.plane != 0 or a.flags & ~(os.O_CLOEXEC | os.O_ACCMODE):
        raise V4L2Error(errno.EINVAL, f"plane {a.plane} / flags {a.flags:#x} are not valid")
    if a.index not in node.shm or a.index >= len(node.driver.queue.slots):
        raise V4L2Error(errno.EINVAL, f"no buffer {a.index}")
    a.fd = -1
    return Answer(0, bytes(a), [node.shm[a.index]])


def _streamon(node: DeviceNode, _f: OpenFile, a: C.c_int) -> None:
    _check(node, a.value)
    node.driver.ioctl(raw.Ioctl.STREAMON)


def _streamoff(node: DeviceNode, _f: OpenFile, a: C.c_int) -> None:
    _check(node, a.value)
    node.driver.ioctl(raw.Ioctl.STREAMOFF)
    node.waiting_for_buffers = True


BUFFER_HANDLERS = {"REQBUFS": _reqbufs, "QUERYBUF": _querybuf, "QBUF": _qbuf, "DQBUF": _dqbuf, "EXPBUF": _expbuf,
                   "STREAMON": _streamon, "STREAMOFF": _streamoff}
"""Buffer request name -> handler(node, file, argument)."""
