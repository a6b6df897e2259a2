"""The videobuf2-like buffer queue of the emulated V4L2 device: states, blocking dequeue, kernel errnos."""

from __future__ import annotations

import collections
import errno
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from rollcam.common.errors import DeviceError
from rollcam.common.lifecycle import Deadline

from .raw import VIDEO_MAX_FRAME, BufFlag, BufType, Field, Memory

MIN_BUFFERS = 2


class V4L2Error(DeviceError, OSError):
    """An ioctl failure carrying the kernel's errno (``exc.errno``), e.g. EAGAIN, EBUSY, EINVAL, ENODEV."""

    def __init__(self, err: int, message: str) -> None:
        OSError.__init__(self, err, f"[{errno.errorcode.get(err, err)}] {message}")

    def __str__(self) -> str:
        return str(self.strerror)


@dataclass
class BufferState:
    """A buffer's state in the queue (what the kernel keeps in ``vb2_buffer``; ``timestamp_ns`` is
    CLOCK_MONOTONIC in integer ns): ``struct v4l2_buffer`` (``raw.Buffer``) is made from it at the device node."""

    index: int
    type: int = BufType.VIDEO_CAPTURE
    bytesused: int = 0
    flags: int = 0
    field: int = Field.NONE
    timestamp_ns: int = 0
    sequence: int = 0
    memory: int = Memory.MMAP
    length: int = 0


@dataclass
class Slot:
    """One buffer: its memory and its current state."""

    info: BufferState
    memory: np.ndarray = field(repr=False)


class BufferQueue:
    """Buffers move dequeued -> queued (QBUF) -> filled by the driver -> done -> dequeued (DQBUF)."""

    def __init__(self, clock: Callable[[], float] = time.monotonic,
                 alloc: Callable[[int, int], np.ndarray] | None = None) -> None:
        self.clock = clock  # what DQBUF timeouts are measured on
        self.alloc = alloc or (lambda _index, size: np.zeros(size, dtype=np.uint8))  # (index, bytes) -> memory
        self.cond = threading.Condition()
        self.slots: list[Slot] = []
        self.queued: collections.deque[int] = collections.deque()
        self.done: collections.deque[int] = collections.deque()
        self.active: set[int] = set()
        self.streaming = False
        self.disconnected = False

    @property
    def busy(self) -> bool:
        """True when buffers are allocated (the format can no longer change, as vb2_is_busy)."""
        return bool(self.slots)

    def request(self, count: int, memory: int, sizeimage: int) -> int:
        """REQBUFS: free every buffer (count 0) or allocate ``count`` (clamped to 2..32); EBUSY while streaming."""
        with self.cond:
            if memory != Memory.MMAP:
                raise V4L2Error(errno.EINVAL, f"memory type {memory!r} is not supported (MMAP only)")
            if self.streaming:
                raise V4L2Error(errno.EBUSY, "REQBUFS while streaming; STREAMOFF first")
            if count < 0:
                raise V4L2Error(errno.EINVAL, f"buffer count {count!r} is negative")
            self.slots, self.active = [], set()
            self.queued.clear()
            self.done.clear()
            if count == 0:
                return 0
            count = min(max(count, MIN_BUFFERS), VIDEO_MAX_FRAME)
            self.slots = [Slot(BufferState(i, flags=BufFlag.MAPPED | BufFlag.TIMESTAMP_MONOTONIC, length=sizeimage),
                               self.alloc(i, sizeimage)) for i in range(count)]
            return count

    def _slot(self, index: int) -> Slot:
        if not 0 <= index < len(self.slots):
            raise V4L2Error(errno.EINVAL, f"buffer index {index!r} is not in 0..{len(self.slots) - 1}"
                            if self.slots else "no buffers allocated (REQBUFS first)")
        return self.slots[index]

    def query(self, index: int) -> BufferState:
        """QUERYBUF: a copy of the buffer's current state."""
        with self.cond:
            info = self._slot(index).info
            return replace(info, flags=int(info.flags))

    def queue(self, index: int) -> None:
        """QBUF: hand an empty buffer to the driver; EINVAL if it is already queued or not dequeued."""
        with self.cond:
            slot = self._slot(index)
            if slot.info.flags & (BufFlag.QUEUED | BufFlag.DONE) or index in self.active:
                raise V4L2Error(errno.EINVAL, f"buffer {index} is already queued")
            slot.info.flags = (slot.info.flags | BufFlag.QUEUED) & ~BufFlag.ERROR
            self.queued.append(index)
            self.cond.notify_all()

    def take(self) -> Slot | None:
        """The driver takes the oldest queued buffer to fill (None when the application queued none)."""
        with self.cond:
            if not self.streaming or not self.queued:
                return None
            index = self.queued.popleft()
            self.active.add(index)
            return self.slots[index]

    def give_back(self, slot: Slot) -> None:
        """The driver returns a buffer unfilled (a dropped frame): it is queued again, at the head."""
        with self.cond:
            if slot.info.index in self.active:
                self.active.discard(slot.info.index)
                self.queued.appendleft(slot.info.index)

    def complete(self, slot: Slot, *, bytesused: int, sequence: int, timestamp_ns: int, error: bool) -> None:
        """The driver finished a buffer: it moves to the done list and wakes DQBUF."""
        with self.cond:
            if slot.info.index not in self.active:
                return  # the queue was reset (STREAMOFF / REQBUFS) while the frame was being filled
            self.active.discard(slot.info.index)
            info = slot.info
            info.bytesused, info.sequence, info.timestamp_ns = bytesused, sequence, timestamp_ns
            info.flags = (info.flags & ~BufFlag.QUEUED) | BufFlag.DONE | BufFlag.TSTAMP_SRC_SOE
            if error:
                info.flags |= BufFlag.ERROR
            self.done.append(info.index)
            self.cond.notify_all()

    def dequeue(self, block: bool = True, timeout_s: float | None = None) -> Slot:
        """DQBUF: the oldest done buffer. EINVAL when not streaming, EAGAIN when non-blocking and none is
        ready, ETIMEDOUT after ``timeout_s``, ENODEV once the device is gone."""
        deadline = Deadline(timeout_s, self.clock)
        with self.cond:
            while True:
                if self.disconnected:
                    raise V4L2Error(errno.ENODEV, "device disconnected")
                if not self.streaming:
                    raise V4L2Error(errno.EINVAL, "DQBUF while not streaming")
                if self.done:
                    slot = self.slots[self.done.popleft()]
                    slot.info.flags &= ~(BufFlag.DONE | BufFlag.QUEUED)
                    return slot
                if not block:
                    raise V4L2Error(errno.EAGAIN, "no buffer ready (non-blocking DQBUF)")
                if deadline.expired:
                    raise V4L2Error(errno.ETIMEDOUT, f"no buffer within {timeout_s} s")
                self.cond.wait(deadline.remaining())

    def start(self) -> None:
        """STREAMON: EINVAL without buffers; a no-op when already streaming."""
        with self.cond:
            if not self.slots:
                raise V4L2Error(errno.EINVAL, "STREAMON without buffers (REQBUFS first)")
            self.streaming = True

    def stop(self) -> None:
        """STREAMOFF: every buffer back to dequeued, waiters woken. Idempotent."""
        with self.cond:
            self.streaming = False
            self.queued.clear()
            self.done.clear()
            self.active.clear()
            for slot in self.slots:
                slot.info.flags &= ~(BufFlag.QUEUED | BufFlag.DONE | BufFlag.ERROR)
            self.cond.notify_all()

    def disconnect(self) -> None:
        """The device is gone: every waiter and later call gets ENODEV."""
        with self.cond:
            self.disconnected = True
            self.cond.notify_all()

