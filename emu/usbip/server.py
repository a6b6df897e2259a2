"""A USB/IP server exporting emulated UVC functions, as Linux's ``usbip list -r`` and ``usbip attach`` expect.

Each TCP connection starts with one operation: OP_REQ_DEVLIST (answered, then closed) or OP_REQ_IMPORT (on
success the connection carries URBs for that device until the peer leaves; ``rollcam.emu.usbip.session``).
A device serves one importer at a time; others are told it is busy (``ST_DEV_BUSY``), and a busid nobody
exports gets ``ST_NODEV``, the statuses Linux's ``usbip`` decodes. A malformed message closes that
connection only; the server keeps serving everyone else.

What peers can hold is bounded (``ServerLimits``): connections at once (one thread each, two more per
import; at the limit the oldest connection still in its first message is dropped to make room, so stalled
peers cannot lock real clients out), the time the first message may take, the time an importer has to send
its first URB, how long an idle importer keeps a device another peer asks for, and the URBs and bytes an
importer may have queued. When accepting fails (no descriptors left: EMFILE, ENFILE), the server says so
once on the ``rollcam.usbip`` logger, backs off and accepts again as descriptors free.
"""

from __future__ import annotations

import contextlib
import logging
import select
import socket
import struct
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass

from rollcam.common.errors import ConfigError, DeviceError, ProtocolError
from rollcam.common.lifecycle import Closeable, Deadline, Stats, Worker
from rollcam.emu.uvc import constants as C
from rollcam.emu.uvc.descriptors import split_descriptors
from rollcam.emu.uvc.device import UVCFunction

from . import protocol as P
from .session import UrbSession

DEFAULT_PORT = 3240
POLL_S = 0.2  # how often a waiting read looks whether the server is closing
BACKLOG = 128
log = logging.getLogger("rollcam.usbip")


@dataclass(frozen=True)
class ServerLimits:
    """What one server grants its peers, whatever they do (seconds, counts, bytes)."""

    max_connections: int = 32  # connections at once
    handshake_timeout_s: float = 5.0  # the whole first operation message (and any later message once begun)
    import_timeout_s: float = 10.0  # from OP_REP_IMPORT to the importer's first URB
    idle_timeout_s: float = 60.0  # an importer idle this long gives its device up to a peer asking for it
    send_timeout_s: float = 30.0  # a reply the peer does not take within this ends its connection
    max_queued_urbs: int = 64  # per importer
    max_urb_bytes: int = 32 * 1024 * 1024  # transfer bytes queued or running per importer (one URB always fits)
    max_backoff_s: float = 1.0  # longest pause between accept attempts while descriptors are exhausted

    def __post_init__(self) -> None:
        for name in ("max_connections", "max_queued_urbs", "max_urb_bytes"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"ServerLimits.{name} must be a whole number >= 1, got {value!r}")
        for name in ("handshake_timeout_s", "import_timeout_s", "idle_timeout_s", "send_timeout_s",
                     "max_backoff_s"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not 0 < value < float("inf"):
                raise ConfigError(f"ServerLimits.{name} must be a finite number of seconds > 0, got {value!r}")


@dataclass
class ServerStats(Stats):
    """Counts a server keeps: connections, lists, imports, refusals, malformed and timed-out peers, URBs,
    connections dropped to make room, idle importers evicted, failed accepts."""

    connections: int = 0
    devlists: int = 0
    imports: int = 0
    refused: int = 0
    malformed: int = 0
    timed_out: int = 0
    shed: int = 0
    evicted: int = 0
    accept_errors: int = 0
    urbs: int = 0
    unlinked: int = 0


@dataclass
class _Export:
    function: UVCFunction
    info: P.ExportedDevice
    owner: _Conn | None = None


def usbip_commands(host: str, port: int, busid: str) -> tuple[str, str]:
    """The Linux ``usbip`` command lines that list a server's devices and attach ``busid`` (``--tcp-port`` is
    an option of ``usbip`` itself, so it goes before the subcommand; attaching needs root and vhci-hcd)."""
    return (f"usbip --tcp-port {port} list -r {host}",
            f"sudo usbip --tcp-port {port} attach -r {host} -b {busid}")


def describe(function: UVCFunction, busnum: int, devnum: int) -> P.ExportedDevice:
    """The device record a USB/IP device list shows for ``function``."""
    dev = struct.unpack("<BBHBBBBHHHBBBB", function.descriptors.device)
    intfs = [(d[5], d[6], d[7]) for d in split_descriptors(function.descriptors.configuration)
             if d[1] == C.DT_INTERFACE and d[3] == 0]
    busid = f"{busnum}-{devnum}"
    return P.ExportedDevice(f"/sys/devices/platform/rollcam/usb{busnum}/{busid}", busid, busnum, devnum,
                            C.SPEED_HIGH, dev[7], dev[8], dev[9], dev[3], dev[4], dev[5], function.configuration or 1,
                            dev[13], tuple(intfs))


class _Conn:
    """One peer's socket, read against deadlines: ``recv(n)`` (a protocol ``RecvExact``) raises TimeoutError
    once ``deadline`` passes and ConnectionError when the peer or the server goes away."""

    def __init__(self, sock: socket.socket, server: USBIPServer) -> None:
        self.sock, self.server = sock, server
        self.opened = time.monotonic()
        self.phase = "handshake"  # then "devlist" or "import"
        try:
            host, port = sock.getpeername()[:2]
            self.peer = f"{host}:{port}"
        except OSError:
            self.peer = "?"
        self.session: UrbSession | None = None
        self.deadline = Deadline(server.limits.handshake_timeout_s)
        self._poll = select.poll()
        self._poll.register(sock, select.POLLIN)
        sock.settimeout(server.limits.send_timeout_s)  # bounds sendall; reads wait in poll below

    def wait_readable(self, deadline: Deadline) -> None:
        """Block until the peer has sent something, ``deadline`` passes (TimeoutError) or the server closes."""
        while not self._poll.poll(deadline.within(POLL_S) * 1000):
            if self.server.closed:
                raise ConnectionError("server closing")
            if deadline.expired:
                raise TimeoutError(f"nothing received within {deadline.seconds:g} s")

    def recv(self, n: int) -> bytes:
        buf = bytearray()
        while len(buf) < n:
            self.wait_readable(self.deadline)
            chunk = self.sock.recv(min(n - len(buf), 1 << 20))
            if not chunk:
                raise ConnectionError("peer closed the connection")
            buf += chunk
        return bytes(buf)

    def next_command(self) -> P.Submit | P.Unlink:
        """The importer's next URB command: the first within the import timeout, later ones whenever they come;
        once a message has begun, all of it within the handshake timeout."""
        limits = self.server.limits
        first = self.session is None or self.session.urbs_received == 0
        self.wait_readable(Deadline(limits.import_timeout_s) if first else Deadline.forever())
        self.deadline = Deadline(limits.handshake_timeout_s)
        return P.read_command(self.recv)

    def abort(self) -> None:
        """Break the connection (its thread sees the peer gone and cleans up)."""
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)


class USBIPServer(Closeable):
    """Serves ``functions`` as busids ``1-1``, ``1-2``, ... on ``host:port`` (port 0 picks a free one), from
    construction until ``close()``, within ``limits``; a context manager."""

    def __init__(self, functions: Sequence[UVCFunction], host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                 *, busnum: int = 1, limits: ServerLimits | None = None) -> None:
        self.limits = limits or ServerLimits()
        self.exports = {}
        for i, f in enumerate(functions, 1):
            info = describe(f, busnum, i)
            self.exports[info.busid] = _Export(f, info)
        self.stats = ServerStats()
        self._lock = threading.Lock()
        self._released = threading.Condition(self._lock)
        self._conns: dict[socket.socket, _Conn] = {}
        self._workers: list[Worker] = []  # one per connection: those alive, and the first that failed
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._sock = socket.create_server((host, port), family=family, backlog=BACKLOG, reuse_port=False)
        self.address: tuple[str, int] = self._sock.getsockname()[:2]
        self._accept = Worker(self._accept_loop, name="usbip-accept", wrap=DeviceError, join_timeout_s=2)
        self._accept.start()

    def __repr__(self) -> str:
        return f"USBIPServer({self.address[0]}:{self.address[1]}, busids={sorted(self.exports)})"

    @property
    def connection_count(self) -> int:
        """Connections being served now."""
        with self._lock:
            return len(self._conns)

    def _close(self) -> None:
        """Stop accepting, drop every connection, reset the devices."""
        with self._lock:
            conns = list(self._conns.values())
        with contextlib.suppress(OSError):
            self._sock.shutdown(socket.SHUT_RDWR)
        self._sock.close()
        for c in conns:
            c.abort()
        with contextlib.ExitStack() as workers:  # each joined; then what failed, if anything did, is raised
            workers.callback(self._accept.close)  # what stopped accepting early
            for w in list(self._workers):
                workers.callback(w.close)  # what broke a connection's thread (not its peer's doing)

    # ------------------------------------------------------------------------------------------ accepting
    def _accept_loop(self) -> None:
        failing_since: float | None = None
        pause = 0.01
        while not self.closed:
            try:
                sock, _peer = self._sock.accept()
            except OSError as exc:
                if self.closed:
                    return
                self.stats.accept_errors += 1
                if failing_since is None:
                    failing_since = time.monotonic()
                    log.warning("USB/IP server %s:%s cannot accept connections (%s); retrying until it can",
                                *self.address, exc)
                self._accept.stop_event.wait(pause)  # back off: the pending connection stays in the backlog
                pause = min(pause * 2, self.limits.max_backoff_s)
                continue
            if failing_since is not None:
                log.warning("USB/IP server %s:%s accepting again after %.1f s", *self.address,
                            time.monotonic() - failing_since)
                failing_since, pause = None, 0.01
            self._admit(sock)

    def _admit(self, sock: socket.socket) -> None:
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        with self._lock:
            if self.closed:
                sock.close()
                return
            self.stats.connections += 1
            if len(self._conns) >= self.limits.max_connections and not self._shed_one():
                self.stats.refused += 1
                sock.close()
                return
            conn = _Conn(sock, self)
            self._conns[sock] = conn
            worker = Worker(self._serve, conn, name="usbip-conn", wrap=DeviceError, join_timeout_s=2)
            failed = [w for w in self._workers if w.error is not None][:1]
            self._workers = failed + [w for w in self._workers if w.alive] + [worker]
        worker.start()

    def _shed_one(self) -> bool:
        """Drop the oldest connection still sending its first message (lock held); False if there is none."""
        waiting = [c for c in self._conns.values() if c.phase == "handshake"]
        if not waiting:
            return False
        victim = min(waiting, key=lambda c: c.opened)
        del self._conns[victim.sock]
        victim.abort()
        self.stats.shed += 1
        return True

    # ------------------------------------------------------------------------------------------ serving
    def _serve(self, conn: _Conn) -> None:
        export = None
        try:
            _version, code, _status = P.read_op_header(conn.recv)
            if code == P.OP_REQ_DEVLIST:
                conn.phase = "devlist"
                # Counted before the reply goes out: a client that has its answer sees the count.
                self.stats.devlists += 1
                conn.sock.sendall(P.rep_devlist([e.info for e in self.exports.values()]))
            elif code == P.OP_REQ_IMPORT:
                busid = P.read_busid(conn.recv)
                conn.phase = "import"
                export, status = self._claim(busid, conn)
                if export is None:
                    self.stats.refused += 1
                    conn.sock.sendall(P.rep_import(None, status))
                else:
                    self.stats.imports += 1
                    conn.session = UrbSession(export.function, export.info.devid, conn.next_command,
                                              conn.sock.sendall, conn.abort,
                                              max_queued_urbs=self.limits.max_queued_urbs,
                                              max_urb_bytes=self.limits.max_urb_bytes, stats=self.stats)
                    conn.sock.sendall(P.rep_import(export.info))
                    conn.session.run()
            else:
                conn.sock.sendall(P.op_header(code & 0x7FFF, P.ST_ERROR))
                raise ProtocolError(f"operation code {code:#06x} is not OP_REQ_DEVLIST or OP_REQ_IMPORT")
        except (ProtocolError, struct.error, UnicodeError) as exc:
            self.stats.malformed += 1
            log.warning("USB/IP peer %s (%s): malformed message, connection closed: %s", conn.peer, conn.phase, exc)
        except TimeoutError as exc:
            self.stats.timed_out += 1
            log.warning("USB/IP peer %s (%s): timed out, connection closed: %s", conn.peer, conn.phase, exc)
        except (ConnectionError, OSError) as exc:
            if export is not None and not self.closed:  # an importer gone: say why, for a kernel that lost its device
                log.info("USB/IP peer %s released %s: %s", conn.peer, export.info.busid, exc or type(exc).__name__)
        finally:
            try:
                if export is not None:
                    export.function.reset()
            finally:  # the camera and the slot are given back even when its reset fails
                with self._lock:
                    if export is not None:
                        export.owner = None
                        self._released.notify_all()
                    self._conns.pop(conn.sock, None)
                with contextlib.suppress(OSError):
                    conn.sock.close()

    def _claim(self, busid: str, conn: _Conn) -> tuple[_Export | None, int]:
        """The export ``busid`` names, now owned by ``conn``; or None and ST_NODEV / ST_DEV_BUSY. An owner idle
        longer than the idle timeout is dropped for the new peer."""
        with self._lock:
            export = self.exports.get(busid)
            if export is None:
                return None, P.ST_NODEV
            owner = export.owner
            if owner is not None and owner.session is not None \
                    and owner.session.idle_s() >= self.limits.idle_timeout_s:
                self.stats.evicted += 1
                owner.abort()
                self._released.wait_for(lambda: export.owner is None, timeout=2.0)
            if export.owner is not None:
                return None, P.ST_DEV_BUSY
            export.owner = conn
            return export, P.ST_OK
