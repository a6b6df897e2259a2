"""File systems that fail on purpose, handed to rollcam's writers through their ``fs`` seam.

``FailingFS`` fails one chosen system call (step k of a run) with ENOSPC, EIO...; ``FullDiskFS`` is a disk that
holds ``capacity`` bytes: the write that crosses it is short, the ones after it fail with ENOSPC. Both count
fsyncs without making them (the tests are about what the writers do on failure, not about the kernel's
durability), so hundreds of runs stay fast.
"""

from __future__ import annotations

import errno
import os

from rollcam.common.files import FileSystem


class FailingFS(FileSystem):
    """Fails the ``fail_at``-th step (1-based; 0: never) with ``err``; ``steps`` counts every step made."""

    def __init__(self, fail_at: int = 0, err: int = errno.ENOSPC) -> None:
        self.fail_at, self.err, self.steps, self.failed = fail_at, err, 0, None

    def _step(self, name: str) -> None:
        self.steps += 1
        if self.steps == self.fail_at:
            self.failed = name
            raise OSError(self.err, os.strerror(self.err))

    def open(self, path, flags, mode=0o666):
        if flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT):
            self._step("open")
        return super().open(path, flags, mode)

    def write(self, fd, data):
        self._step("write")
        return super().write(fd, data)

    def fsync(self, fd):
        self._step("fsync")

    def fsync_dir(self, path):
        self._step("fsync_dir")

    def close(self, fd):
        super().close(fd)  # like close(2) on NFS: the descriptor is gone even when it reports an error
        self._step("close")

    def replace(self, src, dst):
        self._step("replace")
        super().replace(src, dst)


class FullDiskFS(FileSystem):
    """A disk with room for ``capacity`` more bytes: the write that reaches it is short, later ones ENOSPC."""

    def __init__(self, capacity: int) -> None:
        self.room = capacity

    def write(self, fd, data):
        if self.room <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        n = super().write(fd, memoryview(data)[: self.room])
        self.room -= n
        return n

    def fsync(self, fd):
        pass

    def fsync_dir(self, path):
        pass
