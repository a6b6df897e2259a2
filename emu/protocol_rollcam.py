"""pyserial URL handler ``rollcam://``: the camera's control protocol in process, without a pty.

    import serial
    serial.protocol_handler_packages.append("rollcam.emu")
    port = serial.serial_for_url("rollcam://imx219?scene=flat", timeout=1)
    port.write(b"*IDN?\\n"); port.readline()   # b'rollcam,IMX219-EMU,0001,1.0.0\\r\\n'

``rollcam://SENSOR?scene=..&seed=..`` makes a new FirmwareCamera from the emulated camera's option table (the
``emu:`` URI's options; a repeated or unknown option is refused); ``rollcam://NAME`` where NAME was given to
``register_camera`` talks to that camera (so one test can drive a V4L2 device and its serial port).
"""

from __future__ import annotations

import threading
import urllib.parse
from typing import Any

from rollcam.common.errors import ConfigError, RollcamError, require
from rollcam.common.lifecycle import Deadline
from rollcam.common.values import parse_query
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.protocol import ProtocolSession
from rollcam.firmware.spec import CameraSpec

_serialutil = require("serial.serialutil", "pyserial", feature="the rollcam:// serial URL handler")
PortNotOpenError, SerialBase, SerialException = (_serialutil.PortNotOpenError, _serialutil.SerialBase,
                                                 _serialutil.SerialException)

CAMERAS: dict[str, FirmwareCamera] = {}
"""Cameras reachable as ``rollcam://NAME`` (see ``register_camera``)."""
MAX_PENDING = 64 * 1024  # reply bytes kept for a client that does not read; older ones are dropped


def register_camera(name: str, camera: FirmwareCamera) -> None:
    """Make ``camera`` reachable as ``rollcam://name``."""
    CAMERAS[name] = camera


class Serial(SerialBase):
    """A serial port whose far end is an emulated camera's control protocol."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._rx = bytearray()
        self._cond = threading.Condition()
        self.session: ProtocolSession | None = None
        self.dropped_bytes = 0
        super().__init__(*args, **kwargs)

    def open(self) -> None:
        """Open the port: resolve the URL to a camera."""
        if self.is_open:
            raise SerialException("Port is already open.")
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        self.session = ProtocolSession(self._camera_from_url(self.portstr))
        self.is_open = True

    @staticmethod
    def _camera_from_url(url: str) -> FirmwareCamera:
        parts = urllib.parse.urlsplit(url)
        if parts.scheme != "rollcam" or not parts.netloc:
            raise SerialException(f"expected rollcam://SENSOR[?scene=..&seed=..] or rollcam://NAME, got {url!r}")
        try:
            options = parse_query(parts.query, f"URL {url!r}", ConfigError)
            if parts.netloc in CAMERAS:
                if options:
                    raise ConfigError(f"URL {url!r}: rollcam://{parts.netloc} names a registered camera; it takes "
                                      "no options")
                return CAMERAS[parts.netloc]
            return FirmwareCamera(CameraSpec.from_options(parts.netloc, options, f"URL {url!r}"))
        except RollcamError as exc:
            raise SerialException(str(exc)) from None

    def close(self) -> None:
        """Close the port (the camera keeps running). Idempotent."""
        self.is_open = False
        with self._cond:
            self._cond.notify_all()

    def _reconfigure_port(self, *args: Any, **kwargs: Any) -> None:
        """Baud rate and framing mean nothing to an in-process port."""

    @property
    def in_waiting(self) -> int:
        """Reply bytes ready to read."""
        if not self.is_open:
            raise PortNotOpenError()
        return len(self._rx)

    def write(self, data: bytes) -> int:
        """Send command bytes; complete lines are answered at once."""
        if not self.is_open or self.session is None:
            raise PortNotOpenError()
        data = bytes(data)
        reply = self.session.feed(data)
        with self._cond:
            self._rx += reply
            overflow = len(self._rx) - MAX_PENDING
            if overflow > 0:
                del self._rx[:overflow]
                self.dropped_bytes += overflow
            self._cond.notify_all()
        return len(data)

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` reply bytes, waiting at most ``timeout`` seconds (forever when None)."""
        if not self.is_open:
            raise PortNotOpenError()
        deadline = Deadline(self._timeout)
        with self._cond:
            while len(self._rx) < size and self.is_open and not deadline.expired:
                self._cond.wait(deadline.remaining())
            out = bytes(self._rx[:size])
            del self._rx[:size]
            return out

    def reset_input_buffer(self) -> None:
        """Discard unread replies."""
        with self._cond:
            self._rx.clear()

    def reset_output_buffer(self) -> None:
        """Nothing is buffered on the way out."""

    @property
    def out_waiting(self) -> int:
        """Nothing is buffered on the way out."""
        return 0
