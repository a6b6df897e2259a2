"""A USB/IP server exporting emulated UVC functions, as Linux's ``usbip list -r`` and ``usbip attach`` expect.

Each TCP connection starts with one operation: OP_REQ_DEVLIST (answered, then closed) or OP_REQ_IMPORT (on
success the connection carries URBs for that device until the peer leaves). A device serves one importer at
a time; others are told it is busy (``ST_DEV_BUSY``), and a busid nobody exports gets ``ST_NODEV``, the
statuses Linux's ``usbip`` decodes. URBs run in order per endpoint (control, stream) on worker
threads, so CMD_UNLINK can cancel one still queued; the queues are bounded, so a client that floods costs
itself back-pressure, not server memory. A malformed message closes that connection only; the server keeps
serving everyone else.
"""

from __future__ import annotations

import contextlib
import errno
import socket
import struct
import threading
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from rollcam.common.errors import DeviceError, ProtocolError
from rollcam.common.lifecycle import Closeable, Stats, Worker
from rollcam.emu.uvc import constants as C
from rollcam.emu.uvc.descriptors import split_descriptors
from rollcam.emu.uvc.device import Setup, UVCFunction
from rollcam.emu.uvc.requests import Stall
from rollcam.emu.uvc.stream import TransferOverflow, TransferTimeout

from . import protocol as P

DEFAULT_PORT = 3240
MAX_QUEUED_URBS = 64
POLL_MS = 200  # how often a blocked bulk read looks whether the connection is closing


@dataclass
class ServerStats(Stats):
    """Counts a server keeps: connections, lists, imports, refusals, malformed peers, URBs."""

    connections: int = 0
    devlists: int = 0
    imports: int = 0
    refused: int = 0
    malformed: int = 0
    urbs: int = 0
    unlinked: int = 0


@dataclass
class _Export:
    function: UVCFunction
    info: P.ExportedDevice
    owner: object | None = None


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


def _recv_exact(sock: socket.socket) -> Callable[[int], bytes]:
    def recv(n: int) -> bytes:
        buf = bytearray()
        while len(buf) < n:
            chunk = sock.recv(min(n - len(buf), 1 << 20))
            if not chunk:
                raise ConnectionError("peer closed the connection")
            buf += chunk
        return bytes(buf)
    return recv


class USBIPServer(Closeable):
    """Serves ``functions`` as busids ``1-1``, ``1-2``, ... on ``host:port`` (port 0 picks a free one), from
    construction until ``close()``; a context manager."""

    def __init__(self, functions: Sequence[UVCFunction], host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                 *, busnum: int = 1) -> None:
        self.exports = {}
        for i, f in enumerate(functions, 1):
            info = describe(f, busnum, i)
            self.exports[info.busid] = _Export(f, info)
        self.stats = ServerStats()
        self._lock = threading.Lock()
        self._conns: set[socket.socket] = set()
        self._threads: list[threading.Thread] = []
        self._sock = socket.create_server((host, port), reuse_port=False)
        self.address: tuple[str, int] = self._sock.getsockname()[:2]
        self._accept = Worker(self._accept_loop, name="usbip-accept", wrap=DeviceError, join_timeout_s=2)
        self._accept.start()

    def __repr__(self) -> str:
        return f"USBIPServer({self.address[0]}:{self.address[1]}, busids={sorted(self.exports)})"

    def _close(self) -> None:
        """Stop accepting, drop every connection, reset the devices."""
        with self._lock:
            conns = list(self._conns)
        with contextlib.suppress(OSError):
            self._sock.shutdown(socket.SHUT_RDWR)
        self._sock.close()
        for c in conns:
            with contextlib.suppress(OSError):
                c.shutdown(socket.SHUT_RDWR)
        for t in list(self._threads):
            t.join(timeout=2)
        self._accept.close()  # re-raises what stopped accepting early, if anything did

    def _accept_loop(self) -> None:
        while not self.closed:
            try:
                conn, _ = self._sock.accept()
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                if self.closed:
                    conn.close()
                    return
                self._conns.add(conn)
                self.stats.connections += 1
                t = threading.Thread(target=self._serve, args=(conn,), name="usbip-conn", daemon=True)
                self._threads = [x for x in self._threads if x.is_alive()] + [t]
            t.start()

    def _serve(self, conn: socket.socket) -> None:
        recv = _recv_exact(conn)
        export = None
        try:
            _version, code, _status = P.read_op_header(recv)
            if code == P.OP_REQ_DEVLIST:
                conn.sendall(P.rep_devlist([e.info for e in self.exports.values()]))
                self.stats.devlists += 1
            elif code == P.OP_REQ_IMPORT:
                busid = P.read_busid(recv)
                export, status = self._claim(busid, conn)
                if export is None:
                    self.stats.refused += 1
                    conn.sendall(P.rep_import(None, status))
                else:
                    self.stats.imports += 1
                    conn.sendall(P.rep_import(export.info))
                    _UrbSession(conn, recv, export, self).run()
            else:
                conn.sendall(P.op_header(code & 0x7FFF, P.ST_ERROR))
                raise ProtocolError(f"operation code {code:#06x} is not OP_REQ_DEVLIST or OP_REQ_IMPORT")
        except (ProtocolError, struct.error, UnicodeError):
            self.stats.malformed += 1
        except (ConnectionError, OSError):
            pass
        finally:
            if export is not None:
                export.function.reset()
                with self._lock:
                    export.owner = None
            with self._lock:
                self._conns.discard(conn)
            with contextlib.suppress(OSError):
                conn.close()

    def _claim(self, busid: str, conn: socket.socket) -> tuple[_Export | None, int]:
        """The export ``busid`` names, now owned by ``conn``; or None and ST_NODEV / ST_DEV_BUSY."""
        with self._lock:
            export = self.exports.get(busid)
            if export is None:
                return None, P.ST_NODEV
            if export.owner is not None:
                return None, P.ST_DEV_BUSY
            export.owner = conn
            return export, P.ST_OK


def _read_or_none(fn: UVCFunction, ep: int, length: int) -> bytes | None:
    try:
        return fn.read(ep, length, POLL_MS)
    except TransferTimeout:
        return None


@dataclass
class _UrbSession:
    """The URB phase of one imported connection: a reader (this thread) and two in-order workers, one for
    endpoint 0 and one for the streaming endpoint, so control requests are not held behind waiting reads."""

    conn: socket.socket
    recv: Callable[[int], bytes]
    export: _Export
    server: USBIPServer
    queues: tuple[deque, deque] = field(default_factory=lambda: (deque(), deque()))
    frame_number: int = 0

    def __post_init__(self) -> None:
        self.cond = threading.Condition()
        self.send_lock = threading.Lock()
        self.done = False

    def send(self, data: bytes) -> None:
        with self.send_lock:
            self.conn.sendall(data)

    def run(self) -> None:
        workers = [threading.Thread(target=self._work, args=(q,), name="usbip-urbs", daemon=True)
                   for q in self.queues]
        for w in workers:
            w.start()
        try:
            while True:
                cmd = P.read_command(self.recv)
                if isinstance(cmd, P.Unlink):
                    self._unlink(cmd)
                    continue
                with self.cond:
                    while sum(map(len, self.queues)) >= MAX_QUEUED_URBS and not self.done:
                        self.cond.wait(0.5)
                    self.queues[cmd.ep != 0].append(cmd)
                    self.cond.notify_all()
        finally:
            with self.cond:
                self.done = True
                self.cond.notify_all()
            for w in workers:
                w.join(timeout=5)

    def _unlink(self, cmd: P.Unlink) -> None:
        with self.cond:
            hit = next((u for q in self.queues for u in q if u.seqnum == cmd.unlink_seqnum), None)
            if hit is not None:
                self.queues[hit.ep != 0].remove(hit)
                self.server.stats.unlinked += 1
                self.cond.notify_all()
        self.send(P.RetUnlink(cmd.seqnum, -errno.ECONNRESET if hit else 0).pack())

    def _work(self, queue: deque) -> None:
        while True:
            with self.cond:
                while not queue and not self.done:
                    self.cond.wait()
                if self.done:
                    return
                urb = queue.popleft()
                self.cond.notify_all()
            try:
                self.send(self.execute(urb).pack())
            except OSError:
                return
            self.server.stats.urbs += 1

    def execute(self, urb: P.Submit) -> P.RetSubmit:
        """Run one URB against the device; USB errors become negative errno statuses."""
        fn = self.export.function
        n_pkt = urb.number_of_packets
        if urb.devid != self.export.info.devid:
            return P.RetSubmit(urb.seqnum, -errno.ENODEV, number_of_packets=n_pkt)
        try:
            if urb.ep == 0:
                setup = Setup.unpack(urb.setup)
                data = fn.control(setup, urb.data)
                actual = len(data) if setup.is_in else len(urb.data)
                return P.RetSubmit(urb.seqnum, 0, actual, number_of_packets=n_pkt, data=data)
            if urb.direction != P.DIR_IN:
                return P.RetSubmit(urb.seqnum, -errno.EPIPE, number_of_packets=n_pkt)
            if urb.is_iso:
                return self._iso(fn, urb)
            data = self._bulk(fn, urb)
            return P.RetSubmit(urb.seqnum, 0, len(data), number_of_packets=n_pkt, data=data)
        except Stall:
            return P.RetSubmit(urb.seqnum, -errno.EPIPE, number_of_packets=n_pkt)
        except TransferOverflow:
            return P.RetSubmit(urb.seqnum, -errno.EOVERFLOW, number_of_packets=n_pkt)
        except DeviceError:
            return P.RetSubmit(urb.seqnum, -errno.ESHUTDOWN, number_of_packets=n_pkt)

    def _bulk(self, fn: UVCFunction, urb: P.Submit) -> bytes:
        data = None
        while data is None:
            if self.done:
                raise DeviceError("connection closing")
            data = _read_or_none(fn, 0x80 | urb.ep, urb.transfer_buffer_length)
        return data

    def _iso(self, fn: UVCFunction, urb: P.Submit) -> P.RetSubmit:
        n = len(urb.iso)
        size = min((p.length for p in urb.iso), default=0)
        try:
            data, lengths = fn.read_packets(0x80 | urb.ep, n, size)
            status = [0] * n
        except TransferOverflow:
            data, lengths, status = b"", [0] * n, [-errno.EOVERFLOW] * n
        packets = tuple(P.IsoPacket(p.offset, p.length, k, st)
                        for p, k, st in zip(urb.iso, lengths, status, strict=True))
        start = self.frame_number
        self.frame_number = (self.frame_number + n) & 0x3FFF
        return P.RetSubmit(urb.seqnum, 0, len(data), start, n, sum(st != 0 for st in status), data, packets)
