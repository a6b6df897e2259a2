"""``FileOutput``: encoded frames to a file, a file object (a socket's ``makefile``, ``io.BytesIO``), or nowhere."""

from __future__ import annotations

import os
import socket
from collections.abc import Callable
from typing import Any

from .output import Output


class FileOutput(Output):
    """Frames written one after the other to ``file`` (a path, opened here; a writable object; or None).
    A datagram socket's file gets each frame in datagrams of at most ``split`` bytes (65507), as picamera2's.
    An error writing (a peer gone) calls ``connectiondead(exc)`` when set, else is raised."""

    def __init__(self, file: Any = None, pts: Any = None, split: int | None = None) -> None:
        super().__init__(pts=pts)
        self._connectiondead: Callable[[BaseException], None] | None = None
        self._splitsize = split
        self._fileoutput: Any = None
        self.fileoutput = file

    @property
    def fileoutput(self) -> Any:
        """Where frames go."""
        return self._fileoutput

    @fileoutput.setter
    def fileoutput(self, file: Any) -> None:
        self._firstframe, self._needs_close, self._split = True, False, False
        if file is None:
            self._fileoutput = None
        elif isinstance(file, (str, os.PathLike)):
            self._fileoutput = open(file, "wb")  # noqa: SIM115 (open until close)
            self._needs_close = True
        else:
            self._fileoutput = file
            raw = getattr(file, "raw", None)
            sock = getattr(raw, "_sock", None)
            self._split = isinstance(raw, socket.SocketIO) and getattr(sock, "type", None) == socket.SOCK_DGRAM

    @property
    def connectiondead(self) -> Callable[[BaseException], None] | None:
        """Called with the error when writing fails."""
        return self._connectiondead

    @connectiondead.setter
    def connectiondead(self, callback: Callable[[BaseException], None] | None) -> None:
        if callback is not None and not callable(callback):
            raise RuntimeError("Must pass callback function or None")
        self._connectiondead = callback

    def outputframe(self, frame: Any, keyframe: bool = True, timestamp: int | None = None, packet: Any = None,
                    audio: bool = False) -> None:
        """Write a frame; a recording starts at its first keyframe."""
        if audio:
            raise RuntimeError("Writing audio to a file is not supported")
        if self._fileoutput is not None and self.recording:
            if self._firstframe:
                if not keyframe:
                    return
                self._firstframe = False
            self._write(frame, timestamp)

    def stop(self) -> None:
        """Stop recording and close the file (one this output opened)."""
        super().stop()
        self.close()

    def close(self) -> None:
        """Close the file if this output opened it."""
        try:
            if self._needs_close and self._fileoutput is not None:
                self._fileoutput.close()
                self._needs_close = False
        except OSError as exc:
            self._dead(exc)

    def _dead(self, exc: BaseException) -> None:
        if self._connectiondead is None:
            raise exc
        self._connectiondead(exc)

    def _write(self, frame: Any, timestamp: int | None = None) -> None:
        data = memoryview(frame).cast("B")
        try:
            if self._split:
                size = 65507 if self._splitsize is None else self._splitsize
                for off in range(0, len(data), size):
                    self._fileoutput.write(data[off:off + size])
                    self._fileoutput.flush()
            else:
                self._fileoutput.write(data)
                self._fileoutput.flush()
            self.outputtimestamp(timestamp)
        except (ConnectionError, OSError, ValueError) as exc:
            self._dead(exc)
