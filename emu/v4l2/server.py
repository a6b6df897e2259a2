"""The device server the preload library talks to: a Unix socket, one connection per open file.

Wire format (native byte order; the library is ``rollcam.emu.preload``'s C file): a request is a 32-byte
header ``op, len, a, b, c`` and ``len`` bytes; an answer is ``result (i64), errno (i32), len`` and ``len``
bytes, with file descriptors (readiness pipes, memfds) as SCM_RIGHTS. Every request is answered at once
(what blocks, the library waits for on the readiness pipes), so a program's threads never hold up the
device. A connection's end (close, exit or crash of the program) releases its file; a failure in one
request is that request's errno and the server goes on.
"""

from __future__ import annotations

import array
import contextlib
import errno
import logging
import os
import socket
import struct
import threading
from collections.abc import Mapping

from rollcam.common.lifecycle import Closeable

from . import ioctls
from .node import DeviceNode, OpenFile
from .queue import V4L2Error

OP_OPEN, OP_IOCTL, OP_MMAP, OP_READ, OP_POLL, OP_CLOSE = 1, 2, 3, 4, 5, 6
_REQ = struct.Struct("=IIQQQ")
_RSP = struct.Struct("=qiI")
MAX_PAYLOAD = 1 << 16
MAX_CONNECTIONS = 512  # open files per server; v4l2-compliance opens 100 at once
log = logging.getLogger(__name__)


class PreloadServer(Closeable):
    """Serves device nodes by path on a Unix socket (``socket_path``) until closed."""

    def __init__(self, nodes: Mapping[str, DeviceNode], socket_path: str) -> None:
        self.nodes = dict(nodes)
        self.socket_path = socket_path
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.sock.bind(socket_path)
        os.chmod(socket_path, 0o600)
        self.sock.listen(MAX_CONNECTIONS)
        self._conns: set[socket.socket] = set()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._accept, name="rollcam-preload-accept", daemon=True)
        self._thread.start()

    def _close(self) -> None:
        """Stop accepting, drop every connection (their files are released), stop the devices."""
        self._stop.set()
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        self.sock.close()
        self._thread.join(5)
        with self._lock:
            conns = list(self._conns)
        for c in conns:
            with contextlib.suppress(OSError):
                c.shutdown(socket.SHUT_RDWR)
        for node in self.nodes.values():
            node.close()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.socket_path)

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            with self._lock:
                if len(self._conns) >= MAX_CONNECTIONS:
                    conn.close()  # the program's open() gets ENODEV; the others keep their files
                    continue
                self._conns.add(conn)
            threading.Thread(target=self._serve, args=(conn,), name="rollcam-preload-conn", daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        node: DeviceNode | None = None
        f: OpenFile | None = None
        try:
            while True:
                head = _recv(conn, _REQ.size)
                if head is None:
                    return
                op, length, a, b, c = _REQ.unpack(head)
                if length > MAX_PAYLOAD:
                    return  # not our library: drop the connection
                payload = _recv(conn, length) if length else b""
                if payload is None:
                    return
                if op == OP_OPEN:
                    node, f = self._open(conn, payload, a, f)
                    continue
                if op == OP_CLOSE:  # released before the program's close() returns
                    if node is not None and f is not None:
                        node.release(f)
                    node = f = None
                    _send(conn, 0, 0, b"", [])
                    return
                result, err, data, fds = _dispatch(node, f, op, a, b, c, payload)
                _send(conn, result, err, data, fds)
        except OSError:
            return
        finally:
            with self._lock:
                self._conns.discard(conn)
            if node is not None and f is not None:
                node.release(f)
            conn.close()

    def _open(self, conn: socket.socket, payload: bytes, flags: int, f: OpenFile | None
              ) -> tuple[DeviceNode | None, OpenFile | None]:
        node = self.nodes.get(payload.decode(errors="replace"))
        if node is None or f is not None:
            _send(conn, -1, errno.ENODEV, b"", [])
            return None, f
        f = node.open(flags)
        _send(conn, 0, 0, b"", [f.ready.read_fd, f.event.read_fd])
        return node, f


def _dispatch(node: DeviceNode | None, f: OpenFile | None, op: int, a: int, b: int, c: int, payload: bytes
              ) -> tuple[int, int, bytes, list[int]]:
    """One request -> (result, errno, bytes back, fds)."""
    if node is None or f is None:
        return -1, errno.EBADF, b"", []
    try:
        if op == OP_IOCTL:
            ans = ioctls.handle(node, f, a & 0xFFFFFFFF, payload)
            return ans.result, 0, ans.data or b"", ans.fds
        if op == OP_MMAP:
            return 0, 0, b"", [node.mmap(f, a, b, c & 0xFFFFFFFF, c >> 32)]
        if op == OP_READ:
            data = node.read(f, a)
            return len(data), 0, data, []
        if op == OP_POLL:
            return node.poll(f, a, bool(b)), 0, b"", []
        return -1, errno.EINVAL, b"", []
    except V4L2Error as exc:
        return -1, exc.errno or errno.EIO, getattr(exc, "data", b""), []
    except Exception:  # a bug on our side: this call fails with EIO; the device and other files go on
        log.exception("rollcam preload: request %d (%#x) failed", op, a)
        return -1, errno.EIO, b"", []


def _recv(conn: socket.socket, n: int) -> bytes | None:
    buf = bytearray()
    while len(buf) < n:
        chunk = conn.recv(n - len(buf))
        if not chunk:
            return None
        buf += chunk
    return bytes(buf)


def _send(conn: socket.socket, result: int, err: int, data: bytes, fds: list[int]) -> None:
    head = _RSP.pack(result, err, len(data))
    if fds:
        conn.sendmsg([head], [(socket.SOL_SOCKET, socket.SCM_RIGHTS, array.array("i", fds))])
        if data:
            conn.sendall(data)
    else:
        conn.sendall(head + data if len(data) < 65536 else head)
        if len(data) >= 65536:
            conn.sendall(data)
