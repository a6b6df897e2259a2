"""Files that are whole or absent: atomic replacement made durable, append-only JSON-lines logs, checksums.

Every file rollcam writes goes through here. ``write_atomic`` writes a temporary file beside the target,
fsyncs it, renames it over the target and fsyncs the directory, so after a failure at any step (a full disk,
an I/O error, ``kill -9``, power loss) the target holds either its old bytes or all its new ones.
``output_dir`` makes a command's ``--out`` folder (a file in the way is bad usage, one line, exit 2).
``AppendLog`` is a JSON-lines file whose every append is one write of complete lines, cut back to the last
whole line if the write fails; ``read_jsonl`` drops a torn last line that a killed process or a power cut left.

All system calls go through a ``FileSystem`` object (``OS_FS`` by default), so tests hand in one that fails
any chosen call with ``ENOSPC`` or ``EIO``, or that fills up after a given number of bytes.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import io
import json
import os
import secrets
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from .errors import ConfigError
from .lifecycle import Closeable

PART_SUFFIX = ".part"
"""Temporary files end in this; ``.NAME.<token>.part`` sits beside the file NAME it will become."""


class FileSystem:
    """The system calls rollcam's file writers make, one method each; tests pass a subclass that fails some."""

    def open(self, path: str | os.PathLike[str], flags: int, mode: int = 0o666) -> int:
        return os.open(path, flags, mode)

    def write(self, fd: int, data: bytes | memoryview) -> int:
        return os.write(fd, data)

    def fsync(self, fd: int) -> None:
        os.fsync(fd)

    def ftruncate(self, fd: int, length: int) -> None:
        os.ftruncate(fd, length)

    def size(self, fd: int) -> int:
        return os.fstat(fd).st_size

    def close(self, fd: int) -> None:
        os.close(fd)

    def replace(self, src: str | os.PathLike[str], dst: str | os.PathLike[str]) -> None:
        os.replace(src, dst)

    def unlink(self, path: str | os.PathLike[str]) -> None:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(path)

    def fsync_dir(self, path: str | os.PathLike[str]) -> None:
        """Make a rename in ``path`` durable (POSIX; Windows has no directory handles to sync)."""
        if os.name != "posix":
            return
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


OS_FS = FileSystem()


class RenameOnlyFileSystem(FileSystem):
    """Atomic but not durable: a crashed process still leaves files whole or absent, a power cut may lose the
    newest. For bulk exports that are cheap to redo, where an fsync per file would cost more than the work."""

    def fsync(self, fd: int) -> None:
        pass

    def fsync_dir(self, path: str | os.PathLike[str]) -> None:
        pass


RENAME_ONLY_FS = RenameOnlyFileSystem()
_CREATE = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_BINARY", 0)


def write_all(fd: int, data: bytes, fs: FileSystem = OS_FS) -> None:
    """Write all of ``data``; a write that stores nothing (a full disk) is an ``ENOSPC`` error."""
    view = memoryview(data)
    while view:
        n = fs.write(fd, view)
        if n <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        view = view[n:]


def part_path(path: str | os.PathLike[str]) -> Path:
    """A temporary name beside ``path`` that no other writer (process or thread) uses: ``.NAME.<token>.part``."""
    p = Path(path)
    return p.with_name(f".{p.name}.{os.getpid()}-{secrets.token_hex(4)}{PART_SUFFIX}")


def part_target(name: str) -> str | None:
    """The file name a temporary file from ``part_path`` (or an older ``NAME.part``) was to become, else None."""
    if not name.endswith(PART_SUFFIX):
        return None
    stem = name[: -len(PART_SUFFIX)]
    if stem.startswith("."):
        head, _, token = stem[1:].rpartition(".")
        if head and "-" in token:
            return head
    return stem


def commit(part: str | os.PathLike[str], path: str | os.PathLike[str], fs: FileSystem = OS_FS) -> None:
    """Move a finished temporary file (written by another program, say) into place durably; removes ``part``
    and re-raises if any step fails."""
    try:
        fd = fs.open(part, os.O_RDONLY)
        try:
            fs.fsync(fd)
        finally:
            fs.close(fd)
        fs.replace(part, path)
    except BaseException:
        fs.unlink(part)
        raise
    fs.fsync_dir(Path(path).parent)


def commit_tree(staged: str | os.PathLike[str], path: str | os.PathLike[str], fs: FileSystem = OS_FS) -> None:
    """Move a finished file or folder (a ROS 2 bag is a folder) into place durably: every file and folder under
    ``staged`` fsynced, one rename onto ``path`` (which must not be a non-empty folder), the parent fsynced.
    ``staged`` is left where it was if a step fails, for its writer to remove."""
    root = Path(staged)
    tree = [root] if root.is_file() else [*sorted(root.rglob("*"), reverse=True), root]
    for p in tree:
        if p.is_dir():
            fs.fsync_dir(p)
        else:
            fd = fs.open(p, os.O_RDONLY)
            try:
                fs.fsync(fd)
            finally:
                fs.close(fd)
    fs.replace(root, path)
    fs.fsync_dir(Path(path).parent)


def write_atomic(path: str | os.PathLike[str], data: bytes, fs: FileSystem = OS_FS) -> None:
    """Replace ``path`` with ``data`` durably: after any failure it holds its old content or all of ``data``.

    The bytes go to a temporary file that is fsynced, renamed over ``path``, and the rename fsynced in the
    directory. On an error the temporary file is removed and the error re-raised.
    """
    part = part_path(path)
    try:
        fd = fs.open(part, _CREATE, 0o666)
        try:
            write_all(fd, data, fs)
            fs.fsync(fd)
        finally:
            fs.close(fd)
        fs.replace(part, path)
    except BaseException:
        with contextlib.suppress(OSError):
            fs.unlink(part)
        raise
    fs.fsync_dir(Path(path).parent)


def write_figure(path: str | os.PathLike[str], fig: Any, dpi: int = 110, fs: FileSystem = OS_FS) -> None:
    """Write a matplotlib figure to ``path`` as a PNG, atomically (``write_atomic``), and close it: the one figure
    writer of every report (pyplot keeps each figure it made until it is closed)."""
    import matplotlib.pyplot as plt  # only the reports need matplotlib; importing it costs a second

    buf = io.BytesIO()
    try:
        fig.savefig(buf, format="png", dpi=dpi)
    finally:
        plt.close(fig)
    write_atomic(path, buf.getvalue(), fs)


def sha256_file(path: str | os.PathLike[str]) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def file_digest(data: bytes) -> dict[str, Any]:
    """What a commit record stores about a file so a later run can check it: its size and SHA-256."""
    return {"bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()}


def file_matches(path: str | os.PathLike[str], digest: dict[str, Any]) -> bool:
    """Whether ``path`` still holds exactly the bytes ``file_digest`` described (size first: cheap)."""
    try:
        if os.stat(path).st_size != digest.get("bytes"):
            return False
        return sha256_file(path) == digest.get("sha256")
    except OSError:
        return False


def complete_length(data: bytes) -> int:
    """Length of the longest prefix of JSON-lines ``data`` made of whole lines that parse (a torn tail cut)."""
    end = data.rfind(b"\n") + 1
    if end:
        last_start = data.rfind(b"\n", 0, end - 1) + 1
        try:
            json.loads(data[last_start:end])
        except ValueError:  # a line cut and then continued by a later write: drop it as torn too
            return last_start
    return end


def repair_jsonl(path: str | os.PathLike[str], fs: FileSystem = OS_FS) -> int:
    """Cut a torn last line off a JSON-lines file (what a kill or power cut can leave); returns bytes removed."""
    data = Path(path).read_bytes()
    keep = complete_length(data)
    if keep == len(data):
        return 0
    fd = fs.open(path, os.O_WRONLY)
    try:
        fs.ftruncate(fd, keep)
        fs.fsync(fd)
    finally:
        fs.close(fd)
    return len(data) - keep


def read_jsonl(path: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """The records of a JSON-lines file, leaving out a torn last line; a bad line before the last one is an
    error naming it (that is damage, not an interrupted append)."""
    data = Path(path).read_bytes()
    lines = data[: complete_length(data)].splitlines()
    return [_json_line(path, i, line) for i, line in enumerate(lines, 1)]


def _json_line(path: str | os.PathLike[str], number: int, line: bytes) -> dict[str, Any]:
    try:
        return json.loads(line)
    except ValueError as exc:
        raise ValueError(f"{str(path)!r} line {number} is not JSON ({exc}): {line[:80]!r}") from None


class AppendLog(Closeable):
    """A JSON-lines file that only ever holds whole lines, for logs whose lines are commit records.

    Each ``append`` is one write of complete lines on an ``O_APPEND`` descriptor; if it fails (or is
    interrupted) the file is cut back to its last whole line before the error propagates. ``size`` is the
    length of what is committed: a caller that sees it grow knows its lines are in. Opening an existing file
    without ``truncate`` first repairs a torn last line. ``close()`` fsyncs; safe to call twice.
    """

    def __init__(self, path: str | os.PathLike[str], *, truncate: bool = False, fs: FileSystem = OS_FS) -> None:
        self.path, self.fs = Path(path), fs
        if not truncate and self.path.exists():
            repair_jsonl(self.path, fs)
        flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_BINARY", 0)
        self._fd: int | None = fs.open(self.path, flags | (os.O_TRUNC if truncate else 0), 0o666)
        try:
            self.size: int | None = fs.size(self._fd)
        except BaseException:
            self.close()
            raise

    def append(self, lines: bytes) -> None:
        """Add complete lines (``lines`` ends with a newline) in one write, or nothing at all."""
        if not lines.endswith(b"\n"):
            raise ValueError("an append must end with a newline")
        if self._fd is None or self.size is None:
            raise OSError(errno.EBADF, f"{self.path} is closed or was left unusable by a failed rollback")
        try:
            write_all(self._fd, lines, self.fs)
            self.size += len(lines)
        except BaseException:
            self._rollback()
            raise

    def _rollback(self) -> None:
        assert self._fd is not None and self.size is not None
        try:
            self.fs.ftruncate(self._fd, self.size)
        except OSError:
            self.size = None  # the tail is unknown now; readers drop a torn line, and no more appends go in

    def _close(self) -> None:
        """fsync and close (``close()``, from Closeable: once, however often it is called)."""
        if self._fd is not None:
            fd, self._fd = self._fd, None
            try:
                self.fs.fsync(fd)
            finally:
                self.fs.close(fd)


def output_dir(path: str | os.PathLike[str], what: str = "--out", *, make: bool = True) -> Path:
    """``path`` as a folder, made with its parents when missing (``make=False``: only checked, so a command can
    refuse a bad ``--out`` before it starts work): a command's output folder. A file standing at ``path`` or at
    one of its parents is a ``ConfigError`` naming both (bad usage: exit 2), not a raw errno."""
    p = Path(path)
    blocker = next((q for q in (p, *p.parents) if q.exists() and not q.is_dir()), None)
    if blocker is None and make:
        try:
            p.mkdir(parents=True, exist_ok=True)
        except (FileExistsError, NotADirectoryError):  # a file put there meanwhile
            blocker = next((q for q in (p, *p.parents) if q.exists() and not q.is_dir()), p)
    if blocker is not None:
        where = "" if blocker == p else f": {str(blocker)!r} is a file"
        raise ConfigError(f"{what} {str(p)!r} must be a folder, not a file{where}")
    return p


def acquire_lock(path: str | os.PathLike[str], what: str, *, shared: bool = False) -> int | None:
    """Take an advisory ``flock`` on ``path`` (created if needed) and return its descriptor (``release_lock``
    releases it). A lock another process holds is a ``BlockingIOError`` naming ``what`` at once, never a wait.
    A lock taken on a file its holder removed meanwhile (``release_lock(remove=True)``) is dropped and taken again
    on the file now at ``path``, so two processes never both hold ``path``'s lock.
    None where ``fcntl`` is missing (Windows: runs are not protected against each other there)."""
    try:
        import fcntl
    except ImportError:
        return None
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o666)
        try:
            fcntl.flock(fd, (fcntl.LOCK_SH if shared else fcntl.LOCK_EX) | fcntl.LOCK_NB)
            try:
                if os.path.samestat(os.fstat(fd), os.stat(path)):
                    return fd
            except FileNotFoundError:
                pass
        except BlockingIOError:
            os.close(fd)
            raise BlockingIOError(errno.EWOULDBLOCK, f"{what} is in use by another process ({path})") from None
        except BaseException:
            os.close(fd)
            raise
        os.close(fd)  # the holder removed the file between our open and our lock: lock the one there now


def release_lock(fd: int | None, path: str | os.PathLike[str], *, remove: bool = False) -> None:
    """Release a lock ``acquire_lock`` took (None: nothing). ``remove``, for an exclusive lock only: delete the
    lock file first, while still held, so a finished or interrupted run leaves no empty lock file behind."""
    if fd is None:
        return
    try:
        if remove:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(path)
    finally:
        os.close(fd)


@contextlib.contextmanager
def file_lock(path: str | os.PathLike[str], what: str, *, shared: bool = False) -> Iterator[None]:
    """``acquire_lock`` for the ``with`` block."""
    fd = acquire_lock(path, what, shared=shared)
    try:
        yield
    finally:
        release_lock(fd, path)
