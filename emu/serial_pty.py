"""The camera's control protocol on a pseudo-terminal: ``serial.Serial(server.path)`` opens it as a port.

The server owns both ends of a pty (the slave in raw mode: no echo, no line editing), so clients may open
and close the port as often as they like. Replies a client does not read are dropped once the pty's buffer
is full (counted in ``stats.dropped_bytes``), so a stalled client costs no memory. A fault plan
(``faults``, ``rollcam.common.faults``) damages replies as a bad line does: ``drop`` loses reply bytes,
``corrupt`` flips one bit of a byte, ``delay`` holds a reply for ``delay_ms`` (decided by the byte's index
among every reply byte sent, and by the reply's index); ``fault_stats`` counts what it injected.
"""

from __future__ import annotations

import errno
import fcntl
import os
import select
import tty
from dataclasses import dataclass

from rollcam.common.errors import DeviceError
from rollcam.common.faults import FaultInjector, FaultPlan
from rollcam.common.lifecycle import Closeable, Stats, Worker
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.protocol import ProtocolSession


@dataclass
class SerialStats(Stats):
    """Command lines answered, and reply bytes dropped because the client did not read them."""

    lines: int = 0
    dropped_bytes: int = 0


class PtySerialServer(Closeable):
    """Serves ``firmware.protocol`` for one camera on a new pseudo-terminal; a context manager (``with``
    starts it)."""

    def __init__(self, camera: FirmwareCamera, faults: FaultPlan | str | None = None) -> None:
        self.camera = camera
        self.injector = FaultInjector(FaultPlan.of(faults))
        self.fault_stats = self.injector.stats
        self._replies = self._reply_bytes = 0
        self.session = ProtocolSession(camera)
        try:
            self._master, self._slave = os.openpty()
        except OSError as exc:
            raise DeviceError(f"cannot create a pseudo-terminal: {exc}") from None
        tty.setraw(self._slave)
        flags = fcntl.fcntl(self._master, fcntl.F_GETFL)
        fcntl.fcntl(self._master, fcntl.F_SETFL, flags | os.O_NONBLOCK)
        self.path = os.ttyname(self._slave)
        self.stats = SerialStats()
        self._worker = Worker(self._run, name="rollcam-serial", wrap=DeviceError)
        self._stop = self._worker.stop_event

    def __repr__(self) -> str:
        return f"<PtySerialServer {self.path} for {self.camera.sensor.name}{' closed' if self.closed else ''}>"

    def start(self) -> None:
        """Start answering commands."""
        self._check_open()
        self._worker.start()

    _on_enter = start

    def _close(self) -> None:
        """Stop and free the pty (re-raising what stopped the server early, if anything did)."""
        try:
            self._worker.close()
        finally:
            for fd in (self._master, self._slave):
                os.close(fd)

    def _run(self) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([self._master], [], [], 0.1)
            if not ready:
                continue
            try:
                data = os.read(self._master, 4096)
            except BlockingIOError:
                continue
            except OSError as exc:
                if exc.errno == errno.EIO:  # no reader on the slave side right now
                    continue
                raise
            reply = self.session.feed(data)
            self.stats.lines = self.session.lines
            if reply:
                self._send(self._faulted(reply))

    def _faulted(self, reply: bytes) -> bytes:
        """``reply`` as the plan damages it (after holding it, for a delayed reply)."""
        inj = self.injector
        n, self._replies = self._replies, self._replies + 1
        if not inj:
            return reply
        if inj.hit("delay", n):
            self._stop.wait(inj.plan.delay_ms / 1000)
        out = bytearray()
        for i, byte in enumerate(reply, self._reply_bytes):
            if inj.hit("drop", i):
                continue
            if inj.hit("corrupt", i):
                byte ^= 1 << inj.plan.pick("corrupt", i, 8)
            out.append(byte)
        self._reply_bytes += len(reply)
        return bytes(out)

    def _send(self, data: bytes) -> None:
        try:
            sent = os.write(self._master, data)
        except BlockingIOError:
            sent = 0
        self.stats.dropped_bytes += len(data) - sent
