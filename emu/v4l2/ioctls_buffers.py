"""The buffer requests of the ioctl core (vb2's ioctl helpers): REQBUFS, QUERYBUF, QBUF, DQBUF, EXPBUF,
STREAMON and STREAMOFF, with memory and type checks, queue ownership and the ``m.offset`` of shared buffers."""

from __future__ import annotations

import ctypes as C
import errno
import os
from typing import Any

from . import abi, raw
from .node import Answer, DeviceNode, OpenFile
from .queue import V4L2Error

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


def fill(node: DeviceNode, a: abi.Buffer, info: raw.Buffer) -> None:
    """``struct v4l2_buffer`` of a buffer's state."""
    C.memset(C.addressof(a), 0, C.sizeof(a))
    a.index, a.type, a.bytesused, a.field = info.index, node.driver.buf_type, info.bytesused, raw.Field.NONE
    flags = (info.flags & _STATE_FLAGS) | _TIMESTAMP_FLAGS
    if info.index in node.mapped:
        flags |= raw.BufFlag.MAPPED
    a.flags = int(flags)
    a.timestamp.tv_sec, usec = divmod(info.timestamp_ns // 1000, 1_000_000)
    a.timestamp.tv_usec = usec
    a.sequence, a.memory, a.length = info.sequence, raw.Memory.MMAP, info.length
    a.m.offset = node.offset(info.index)


def _reqbufs(node: DeviceNode, f: OpenFile, a: abi.RequestBuffers) -> None:
    _check(node, a.type)
    if a.memory != raw.Memory.MMAP:
        raise V4L2Error(errno.EINVAL, f"memory {a.memory} is not supported (MMAP only)")
    d = node.driver
    if d.queue.streaming:
        raise V4L2Error(errno.EBUSY, "REQBUFS while streaming")
    count = d.ioctl(raw.Ioctl.REQBUFS, raw.RequestBuffers(a.count)).count
    node.reallocated()
    node.owner = f if count else None
    node.waiting_for_buffers = True
    a.count, a.capabilities, a.flags = count, BUF_CAP_SUPPORTS_MMAP | BUF_CAP_SUPPORTS_ORPHANED_BUFS, 0
    a.reserved[:] = [0, 0, 0]


def _querybuf(node: DeviceNode, _f: OpenFile, a: abi.Buffer) -> None:
    _check(node, a.type)
    fill(node, a, node.driver.ioctl(raw.Ioctl.QUERYBUF, raw.Buffer(a.index)))


def _qbuf(node: DeviceNode, _f: OpenFile, a: abi.Buffer) -> None:
    _check(node, a.type, a.memory)
    if a.flags & FLAG_REQUEST_FD:
        raise V4L2Error(errno.EBADR, "this device has no requests (media request API)")
    fill(node, a, node.driver.ioctl(raw.Ioctl.QBUF, raw.Buffer(a.index)))
    node.waiting_for_buffers = False


def _dqbuf(node: DeviceNode, _f: OpenFile, a: abi.Buffer) -> None:
    _check(node, a.type, a.memory)
    slot = node.driver.ioctl(raw.Ioctl.DQBUF, {"block": False})
    fill(node, a, slot.info)


def _expbuf(node: DeviceNode, _f: OpenFile, a: abi.ExportBuffer) -> Any:
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
