"""One emulated ``/dev/videoN`` as the kernel's V4L2 core and videobuf2 present it to open files.

``DeviceNode`` wraps an ``EmuDriver`` with what lives above a driver in Linux: open file handles, the queue's
owner (the file that allocated buffers; others get EBUSY), priorities, events, buffers in shared memory
(one memfd per buffer, mapped by the program), ``read()`` I/O (vb2's file I/O emulation) and the poll mask.
Each open file has two readiness pipes the server keeps level: ``ready`` is readable while a blocking DQBUF
or read would return, ``event`` while an event is pending. ``rollcam.emu.v4l2.ioctls`` decodes the requests.
"""

from __future__ import annotations

import errno
import fcntl
import mmap
import os
import select
import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import ctrls, raw
from .driver import EmuDriver
from .events import Events, diff
from .queue import Slot, V4L2Error

PAGE = mmap.PAGESIZE
READ_BUFFERS = 3
PRIO_BACKGROUND, PRIO_INTERACTIVE, PRIO_RECORD = 1, 2, 3
_MAP_SHARED_MASK = 0x03  # MAP_SHARED (1) or MAP_SHARED_VALIDATE (3)


class Level:
    """A pipe whose read end is readable exactly while ``set(True)`` holds; the program polls the read end."""

    def __init__(self) -> None:
        self.read_fd, self._write_fd = os.pipe2(os.O_CLOEXEC)
        self.on = False

    def set(self, on: bool) -> None:
        if on and not self.on:
            os.write(self._write_fd, b"x")
        elif not on and self.on:
            os.read(self.read_fd, 1)  # the one byte written: never blocks
        self.on = on

    def close(self) -> None:
        for fd in (self.read_fd, self._write_fd):
            os.close(fd)


@dataclass
class Answer:
    """What goes back to the program from one ioctl: the return value, the argument's bytes (None: nothing
    copied back), and file descriptors (EXPBUF)."""

    result: int = 0
    data: bytes | None = None
    fds: list[int] = field(default_factory=list)


@dataclass(eq=False)
class OpenFile:
    """One open() of the node: its priority, events and readiness pipes."""

    flags: int
    priority: int = PRIO_INTERACTIVE
    events: Events = field(default_factory=Events)
    ready: Level = field(default_factory=Level)
    event: Level = field(default_factory=Level)


@dataclass
class FileIO:
    """vb2's read() emulation: the buffer being read and how far."""

    slot: Slot | None = None
    pos: int = 0


class DeviceNode:
    """The device node of one emulated camera: files, queue ownership, shared buffers, poll and read."""

    def __init__(self, driver: EmuDriver, path: str = "/dev/video0", minor: int = 0) -> None:
        self.driver = driver
        self.path, self.minor = path, minor
        self.bus_minor = minor  # QUERYCAP's bus_info: a metadata node shares its image node's (one device)
        self.lock = threading.RLock()
        self._levels = threading.Lock()  # sync() runs on the pump's thread too: it must not wait for self.lock
        self.files: list[OpenFile] = []
        self.owner: OpenFile | None = None
        self.fileio: FileIO | None = None
        self.shm: dict[int, int] = {}  # buffer index -> memfd
        self.stride, self.mapped = 0, set()  # bytes between buffer offsets (page-aligned); mapped indices
        self.waiting_for_buffers = True
        driver.queue.alloc = self._alloc
        driver.on_change = self.sync

    def __repr__(self) -> str:
        return f"<DeviceNode {self.path} {self.driver.camera!r}, {len(self.files)} open>"

    # ------------------------------------------------------------------------------------ files
    def open(self, flags: int) -> OpenFile:
        """A new file handle."""
        with self.lock:
            f = OpenFile(flags)
            with self._levels:
                self.files.append(f)
            self.sync()
            return f

    def release(self, f: OpenFile) -> None:
        """The file was closed (or its program died): if it owned the queue, streaming stops and buffers go."""
        with self.lock:
            if f not in self.files:
                return
            if self.owner is f:
                self.free_queue()
            with self._levels:
                self.files.remove(f)
                f.ready.close()
                f.event.close()
            if not self.files and self.driver.queue.disconnected:
                self.driver.close()  # vivid: an unplugged device is connected again once its last file closes
            self.sync()

    def free_queue(self) -> None:
        """STREAMOFF and REQBUFS 0 for the owner; nobody owns the queue after."""
        with self.lock:
            has_controls = self.driver.buf_type == raw.BufType.VIDEO_CAPTURE  # a metadata node has none
            before = ctrls.controls(self.driver) if has_controls else {}
            try:
                self.driver.ioctl(raw.Ioctl.STREAMOFF)
                self.driver.ioctl(raw.Ioctl.REQBUFS, raw.RequestBuffers(0, memory=raw.Memory.MMAP))
            except V4L2Error:
                pass  # a disconnected device: nothing left to stop
            self._free_shm()
            self.owner, self.fileio = None, None
            self.waiting_for_buffers = True
            if has_controls:
                self.notify_controls(before, None)

    def check_owner(self, f: OpenFile) -> None:
        """EBUSY when another file owns the queue (vb2_queue_is_busy)."""
        if self.owner is not None and self.owner is not f:
            raise V4L2Error(errno.EBUSY, "another open file owns the buffers")

    def check_priority(self, f: OpenFile) -> None:
        """EBUSY when another file holds a higher priority (v4l2_prio_check)."""
        top = max((g.priority for g in self.files), default=PRIO_INTERACTIVE)
        if f.priority < top:
            raise V4L2Error(errno.EBUSY, f"another open file has priority {top}")

    def notify_controls(self, before: dict[int, ctrls.Ctrl], by: OpenFile | None) -> None:
        """Queue the control events of what changed since ``before``."""
        after = ctrls.controls(self.driver)
        changed = diff(before, after)
        if changed:
            for g in self.files:
                g.events.notify(changed, after, g is by)
            self.sync()

    # ------------------------------------------------------------------------------------ memory
    def _alloc(self, index: int, size: int) -> np.ndarray:
        """Buffer memory for the queue: a memfd the program maps (the one copy of each frame is the fill),
        sealed at its size as a dma-buf is fixed: a program's ftruncate of an EXPBUF'd buffer fails (EPERM)
        instead of making this process's fill fault (SIGBUS) and every device die with it."""
        length = -(-size // PAGE) * PAGE
        fd = os.memfd_create(f"rollcam-v4l2-{self.minor}-{index}", os.MFD_CLOEXEC | os.MFD_ALLOW_SEALING)
        os.ftruncate(fd, length)
        fcntl.fcntl(fd, fcntl.F_ADD_SEALS, fcntl.F_SEAL_SHRINK | fcntl.F_SEAL_GROW | fcntl.F_SEAL_SEAL)
        old = self.shm.pop(index, None)
        if old is not None:
            os.close(old)
        self.shm[index] = fd
        self.stride = length
        return np.frombuffer(mmap.mmap(fd, length), np.uint8, count=size)

    def _free_shm(self) -> None:
        for fd in self.shm.values():
            os.close(fd)  # the program's mappings keep their memory until it unmaps them
        self.shm.clear()
        self.mapped.clear()

    def reallocated(self) -> None:
        """After REQBUFS: memfds of buffers that no longer exist are closed."""
        n = len(self.driver.queue.slots)
        for index in [i for i in self.shm if i >= n]:
            os.close(self.shm.pop(index))
        self.mapped = {i for i in self.mapped if i < n}

    def offset(self, index: int) -> int:
        """``m.offset`` of buffer ``index`` (vb2: page-aligned lengths one after another)."""
        return index * self.stride

    def mmap(self, f: OpenFile, offset: int, length: int, prot: int, flags: int) -> int:
        """The memfd to map for ``mmap(offset, length)``, with vb2_mmap's checks; the file offset is 0."""
        with self.lock:
            if self.fileio is not None:
                raise V4L2Error(errno.EBUSY, "mmap while read() I/O is in progress")
            if flags & _MAP_SHARED_MASK not in (1, 3):
                raise V4L2Error(errno.EINVAL, "buffers must be mapped MAP_SHARED")
            if not prot & mmap.PROT_READ:
                raise V4L2Error(errno.EINVAL, "a capture buffer must be mapped PROT_READ")
            n = len(self.driver.queue.slots)
            index = offset // self.stride if self.stride else -1
            if not 0 <= index < n or offset % self.stride or index not in self.shm:
                raise V4L2Error(errno.EINVAL, f"no buffer at offset {offset:#x}")
            if length > self.stride or length == 0:
                raise V4L2Error(errno.EINVAL, f"length {length} is larger than the buffer ({self.stride})")
            self.mapped.add(index)
            return self.shm[index]

    # ------------------------------------------------------------------------------------ readiness
    def sync(self) -> None:
        """Set every file's readiness pipes from the queue's state (called after each change, also by the
        pump's thread when a buffer completes: so without ``self.lock``, which STREAMOFF holds while it waits
        for the pump to stop)."""
        with self._levels:
            q = self.driver.queue
            ready = not q.streaming or q.disconnected or bool(q.done)
            for f in list(self.files):
                f.ready.set(ready)
                f.event.set(bool(f.events.pending) or q.disconnected)

    def poll(self, f: OpenFile, events: int, start: bool) -> int:
        """The poll mask vb2_fop_poll gives for ``events`` (``start``: POLLIN may start read() I/O)."""
        with self.lock:
            q = self.driver.queue
            if q.disconnected:
                return select.POLLERR | select.POLLHUP | select.POLLPRI
            mask = select.POLLPRI if f.events.pending else 0
            if not events & (select.POLLIN | select.POLLRDNORM):
                return mask
            if start and not q.slots and self.fileio is None and self.owner is None \
                    and self.driver.buf_type == raw.BufType.VIDEO_CAPTURE:
                try:
                    _start_fileio(self, f)
                except V4L2Error:
                    return mask | select.POLLERR
            if not q.streaming or self.waiting_for_buffers:
                return mask | select.POLLERR
            if q.done:
                mask |= select.POLLIN | select.POLLRDNORM
            return mask

    # ------------------------------------------------------------------------------------ read() I/O
    def read(self, f: OpenFile, count: int) -> bytes:
        """read(): the next frame's bytes (or the rest of the one being read); EAGAIN while none is ready."""
        with self.lock:
            if self.driver.buf_type != raw.BufType.VIDEO_CAPTURE:
                raise V4L2Error(errno.EINVAL, "a metadata node has no read() I/O")
            if self.fileio is None:
                if self.driver.queue.slots or self.owner is not None:
                    raise V4L2Error(errno.EBUSY, "read() while streaming I/O owns the buffers")
                _start_fileio(self, f)
            self.check_owner(f)
            io = self.fileio
            assert io is not None
            if io.slot is None:
                io.slot = self.driver.ioctl(raw.Ioctl.DQBUF, {"block": False})
                io.pos = 0
                self.sync()
            slot = io.slot
            end = min(slot.info.bytesused, io.pos + count)
            data = slot.memory[io.pos:end].tobytes()
            io.pos = end
            if io.pos >= slot.info.bytesused:
                io.slot = None
                self.driver.ioctl(raw.Ioctl.QBUF, raw.Buffer(slot.info.index))
            return data

    def close(self) -> None:
        """Release every file and stop the device."""
        with self.lock:
            for f in list(self.files):
                self.release(f)
            self.driver.close()
            self._free_shm()


def _start_fileio(node: DeviceNode, f: OpenFile) -> None:
    """vb2's read() emulation starts: buffers allocated, queued and streaming, owned by ``f``."""
    d = node.driver
    d.ioctl(raw.Ioctl.REQBUFS, raw.RequestBuffers(READ_BUFFERS, memory=raw.Memory.MMAP))
    node.reallocated()
    for i in range(len(d.queue.slots)):
        d.ioctl(raw.Ioctl.QBUF, raw.Buffer(i))
    d.ioctl(raw.Ioctl.STREAMON)
    node.owner, node.fileio, node.waiting_for_buffers = f, FileIO(), False
    node.sync()


def describe(node: DeviceNode) -> dict[str, Any]:
    """What a log line or ``rollcam run --json`` says about a node."""
    cam = node.driver.camera
    if node.driver.buf_type != raw.BufType.VIDEO_CAPTURE:
        from .meta import META_FOURCC

        return {"path": node.path, "sensor": cam.sensor.name, "metadata": META_FOURCC}
    return {"path": node.path, "sensor": cam.sensor.name, "size": list(cam.size), "format": cam.pixel_format}
