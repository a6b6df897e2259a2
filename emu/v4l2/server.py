"""The device server the preload library talks to: a Unix socket, one connection per open file.

The wire format is ``rollcam.emu.preload.wire`` (read from ``rollcam_wire.h``, the C library's header):
each connection starts with a hello each way, and a library from another build is refused with a log line
naming both versions. Every request is answered at once (what blocks, the library waits for on the readiness
pipes), so a program's threads never hold up the device. An open file can have several connections (a forked
child gets its own, ``OP_ATTACH``); it is released when the last one closes or ends (exit or crash of the
program). A failure in one request is that request's errno and the server goes on; a connection that breaks
the protocol is refused or dropped, releasing what it held.
"""

from __future__ import annotations

import array
import contextlib
import errno
import logging
import os
import secrets
import socket
import threading
from collections.abc import Mapping
from dataclasses import dataclass

from rollcam.common.errors import DeviceError
from rollcam.common.lifecycle import Closeable, Worker
from rollcam.emu.preload.wire import HELLO, MAGIC, MAX_PAYLOAD, REQ, RSP, VERSION, Op

from . import ioctls
from .node import DeviceNode, OpenFile
from .queue import V4L2Error

MAX_CONNECTIONS = 512  # connections per server; v4l2-compliance opens 100 at once
log = logging.getLogger(__name__)


@dataclass(eq=False)
class SharedFile:
    """One open file of a node and how many connections share it (a process and its forked children)."""

    id: int
    node: DeviceNode
    file: OpenFile
    links: int = 1


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
        self._files: dict[int, SharedFile] = {}
        self._lock = threading.Lock()
        self._workers: list[Worker] = []  # one per connection: those alive, and the first that failed
        self._accepting = Worker(self._accept, name="rollcam-preload-accept", wrap=DeviceError, join_timeout_s=5)
        self._accepting.start()

    def _close(self) -> None:
        """Stop accepting, drop every connection (their files are released), stop the devices; then raise what
        broke the accepting thread or a connection's, if anything did (a peer's doing only ends its connection)."""
        self._accepting.stop()
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        self.sock.close()
        with contextlib.ExitStack() as steps:  # last registered runs first; each runs whatever the others raise
            steps.callback(self._remove_socket_file)
            for node in self.nodes.values():
                steps.callback(node.close)
            steps.callback(self._drop_connections)
            steps.callback(self._accepting.close)  # first: no connection is accepted after the drop

    def _drop_connections(self) -> None:
        with self._lock:
            conns, workers = list(self._conns), list(self._workers)
        for c in conns:
            with contextlib.suppress(OSError):
                c.shutdown(socket.SHUT_RDWR)
        with contextlib.ExitStack() as joined:
            for w in workers:
                joined.callback(w.close)

    def _remove_socket_file(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.socket_path)

    def open_files(self) -> int:
        """How many open files the connections hold now (for tests and logs)."""
        with self._lock:
            return len(self._files)

    def _accept(self) -> None:
        while not self._accepting.stopping:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            with self._lock:
                if len(self._conns) >= MAX_CONNECTIONS:
                    conn.close()  # the program's open() gets ENODEV; the others keep their files
                    continue
                self._conns.add(conn)
                worker = Worker(self._serve, conn, name="rollcam-preload-conn", wrap=DeviceError, join_timeout_s=5)
                failed = [w for w in self._workers if w.error is not None][:1]
                self._workers = failed + [w for w in self._workers if w.alive] + [worker]
            worker.start()

    def _serve(self, conn: socket.socket) -> None:
        shared: SharedFile | None = None
        try:
            if not _hello(conn):
                return
            while True:
                head = _recv(conn, REQ.size)
                if head is None:
                    return
                op, length, a, b, c = REQ.unpack(head)
                if length > MAX_PAYLOAD:
                    log.warning("rollcam preload: a request of %d bytes (most: %d): connection dropped",
                                length, MAX_PAYLOAD)
                    return
                payload = _recv(conn, length) if length else b""
                if payload is None:
                    return
                if op in (Op.OPEN, Op.ATTACH):
                    if shared is not None:  # one file per connection: the first stays as it is
                        log.warning("rollcam preload: a second OPEN/ATTACH on one connection: refused")
                        _send(conn, -1, errno.EPROTO, b"", [])
                        continue
                    shared = self._open(payload, a) if op == Op.OPEN else self._attach(a)
                    if shared is None:
                        _send(conn, -1, errno.ENODEV, b"", [])
                    elif op == Op.OPEN:
                        _send(conn, shared.id, 0, b"", [shared.file.ready.read_fd, shared.file.event.read_fd])
                    else:
                        _send(conn, 0, 0, b"", [])
                    continue
                if op == Op.CLOSE:  # released before the program's close() returns, when this was the last
                    self._leave(shared)
                    shared = None
                    _send(conn, 0, 0, b"", [])
                    return
                result, err, data, fds = _dispatch(shared, op, a, b, c, payload)
                _send(conn, result, err, data, fds)
        except OSError:
            return
        finally:
            with self._lock:
                self._conns.discard(conn)
            self._leave(shared)
            conn.close()

    def _open(self, payload: bytes, flags: int) -> SharedFile | None:
        """A new open file of the node at the path ``payload`` names (None: no such node)."""
        node = self.nodes.get(payload.decode(errors="replace"))
        if node is None:
            return None
        shared = SharedFile(secrets.randbits(62), node, node.open(flags))
        with self._lock:
            self._files[shared.id] = shared
        return shared

    def _attach(self, file_id: int) -> SharedFile | None:
        """One more connection to the open file ``file_id`` (None: it is released or never was)."""
        with self._lock:
            shared = self._files.get(file_id)
            if shared is not None:
                shared.links += 1
            return shared

    def _leave(self, shared: SharedFile | None) -> None:
        """A connection leaves its file; the last one out releases it."""
        if shared is None:
            return
        with self._lock:
            shared.links -= 1
            last = shared.links == 0
            if last:
                del self._files[shared.id]
        if last:
            shared.node.release(shared.file)


def _hello(conn: socket.socket) -> bool:
    """The connection's first exchange: True when the library speaks this server's wire format."""
    head = _recv(conn, HELLO.size)
    if head is None:
        return False
    magic, version = HELLO.unpack(head)
    conn.sendall(HELLO.pack(MAGIC, VERSION))
    if (magic, version) != (MAGIC, VERSION):
        log.warning("rollcam preload: a program's library speaks wire format %d (magic %#x), this server %d: "
                    "reinstall rollcam so that both come from one build", version, magic, VERSION)
        return False
    return True


def _dispatch(shared: SharedFile | None, op: int, a: int, b: int, c: int, payload: bytes
              ) -> tuple[int, int, bytes, list[int]]:
    """One request -> (result, errno, bytes back, fds)."""
    if shared is None:
        return -1, errno.EBADF, b"", []
    node, f = shared.node, shared.file
    try:
        if op == Op.IOCTL:
            ans = ioctls.handle(node, f, a & 0xFFFFFFFF, payload)
            return ans.result, 0, ans.data or b"", ans.fds
        if op == Op.MMAP:
            return 0, 0, b"", [node.mmap(f, a, b, c & 0xFFFFFFFF, c >> 32)]
        if op == Op.READ:
            data = node.read(f, a)
            return len(data), 0, data, []
        if op == Op.POLL:
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
    head = RSP.pack(result, err, len(data))
    if fds:
        conn.sendmsg([head], [(socket.SOL_SOCKET, socket.SCM_RIGHTS, array.array("i", fds))])
        if data:
            conn.sendall(data)
    else:
        conn.sendall(head + data if len(data) < 65536 else head)
        if len(data) >= 65536:
            conn.sendall(data)
