"""``CircularOutput``: the last few seconds of encoded frames kept in memory, written out from a keyframe
when a file is given and ``start()`` is called (record what happened before a trigger)."""

from __future__ import annotations

import collections
import threading
from typing import Any

from .fileoutput import FileOutput


class CircularOutput(FileOutput):
    """A ring of the last ``buffersize`` frames (150: five seconds at 30 fps). With ``fileoutput`` set and
    recording, the ring goes to the file from its oldest keyframe on, and every new frame follows."""

    def __init__(self, file: Any = None, pts: Any = None, buffersize: int = 30 * 5, outputtofile: bool = True) -> None:
        self._lock = threading.Lock()
        self.buffersize = buffersize
        self.outputtofile = outputtofile
        super().__init__(file, pts=pts)

    @property
    def buffersize(self) -> int:
        """How many frames the ring holds."""
        return self._buffersize

    @buffersize.setter
    def buffersize(self, value: int) -> None:
        if not isinstance(value, int):
            raise RuntimeError("Buffer size must be integer")
        with self._lock:
            self._buffersize = value
            self._circular: collections.deque[tuple[bytes, bool, int | None]] = collections.deque(maxlen=value)

    def outputframe(self, frame: Any, keyframe: bool = True, timestamp: int | None = None, packet: Any = None,
                    audio: bool = False) -> None:
        """Keep the frame in the ring; while writing to a file, write the ring's oldest frames out."""
        if audio:
            raise RuntimeError("CircularOutput does not support audio")
        with self._lock:
            if self._buffersize == 0:
                return
            self._circular.append((bytes(memoryview(frame).cast("B")), keyframe, timestamp))
            if self._fileoutput is None or not self.recording or not self.outputtofile:
                return
            out = self._drain(keep=0)
        for data, stamp in out:
            self._write(data, stamp)

    def _drain(self, keep: int) -> list[tuple[bytes, int | None]]:
        """Frames to write now (under the lock): the first from a keyframe on, leaving ``keep`` in the ring."""
        out = []
        while len(self._circular) > keep:
            data, key, stamp = self._circular.popleft()
            if self._firstframe and not key:
                continue
            self._firstframe = False
            out.append((data, stamp))
        return out

    def stop(self) -> None:
        """Write what is left in the ring, then stop recording and close the file."""
        if not self.recording or self._fileoutput is None:
            self.recording = False
            return
        with self._lock:
            out = self._drain(keep=0)
        for data, stamp in out:
            self._write(data, stamp)
        self._firstframe = False
        super().stop()
