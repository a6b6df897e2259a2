"""The camera's control protocol on a pseudo-terminal: ``serial.Serial(server.path)`` opens it as a port.

The server owns both ends of a pty (the slave in raw mode: no echo, no line editing), so clients may open
and close the port as often as they like. Replies a client does not read are dropped once the pty's buffer
is full (counted in ``stats['dropped_bytes']``), so a stalled client costs no memory.
"""

from __future__ import annotations

import errno
import fcntl
import os
import select
import threading
import tty

from rollcam.common.errors import DeviceError
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.protocol import ProtocolSession


class PtySerialServer:
    """Serves ``firmware.protocol`` for one camera on a new pseudo-terminal; a context manager."""

    def __init__(self, camera: FirmwareCamera) -> None:
        self.camera = camera
        self.session = ProtocolSession(camera)
        try:
            self._master, self._slave = os.openpty()
        except OSError as exc:
            raise DeviceError(f"cannot create a pseudo-terminal: {exc}") from None
        tty.setraw(self._slave)
        flags = fcntl.fcntl(self._master, fcntl.F_GETFL)
        fcntl.fcntl(self._master, fcntl.F_SETFL, flags | os.O_NONBLOCK)
        self.path = os.ttyname(self._slave)
        self.stats = {"lines": 0, "dropped_bytes": 0}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="rollcam-serial", daemon=True)
        self.closed = False

    def __enter__(self) -> PtySerialServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<PtySerialServer {self.path} for {self.camera.sensor.name}{' closed' if self.closed else ''}>"

    def start(self) -> None:
        """Start answering commands."""
        self._thread.start()

    def close(self) -> None:
        """Stop and free the pty. Idempotent."""
        if self.closed:
            return
        self.closed = True
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5)
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
            self.stats["lines"] = self.session.lines
            if reply:
                self._send(reply)

    def _send(self, data: bytes) -> None:
        try:
            sent = os.write(self._master, data)
        except BlockingIOError:
            sent = 0
        self.stats["dropped_bytes"] += len(data) - sent
