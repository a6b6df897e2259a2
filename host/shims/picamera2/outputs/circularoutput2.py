"""``CircularOutput2``: the last ``buffer_duration_ms`` of encoded frames, handed to any output opened with
``open_output`` (from the ring's oldest keyframe on, timestamps counted from it), until ``close_output``."""

from __future__ import annotations

import collections
import threading
from typing import Any

from .output import Output


class CircularOutput2(Output):
    """A time-windowed ring of frames in front of another output (a ``PyavOutput``, a ``FileOutput``)."""

    def __init__(self, pts: Any = None, buffer_duration_ms: int = 5000) -> None:
        super().__init__(pts=pts)
        if buffer_duration_ms < 0:
            raise RuntimeError("buffer_duration_ms may not be negative")
        self._lock = threading.Lock()
        self.buffer_duration_ms = buffer_duration_ms
        self._ring: collections.deque[tuple[Any, bool, int, Any, bool]] = collections.deque()
        self._output: Output | None = None
        self._streams: list[tuple[str, str, dict[str, Any]]] = []
        self._first_frame, self._offset = True, 0

    def open_output(self, output: Output) -> None:
        """Start writing the ring, and the frames that follow, to ``output``."""
        if self._output is not None:
            raise RuntimeError("Underlying output must be closed first")
        for encoder_stream, codec, kwargs in self._streams:
            output._add_stream(encoder_stream, codec, **kwargs)
        output.start()
        with self._lock:
            self._output, self._first_frame = output, True

    def close_output(self) -> None:
        """Stop writing to the output opened, and stop it."""
        if self._output is None:
            raise RuntimeError("No underlying output has been opened")
        with self._lock:
            output, self._output = self._output, None
        output.stop()

    def _flush(self, now_us: int | None, output: Output | None) -> None:
        """Drop the frames older than the window (all when ``now_us`` is None), writing them to ``output``."""
        while self._ring:
            frame, keyframe, stamp, packet, audio = self._ring[0]
            if now_us is not None and now_us - stamp < self.buffer_duration_ms * 1000:
                break
            self._ring.popleft()
            if keyframe and not audio and self._first_frame:
                self._offset, self._first_frame = stamp, False
            if not self._first_frame and output is not None and stamp >= self._offset:
                output.outputframe(frame, keyframe, stamp - self._offset, packet, audio)

    def outputframe(self, frame: Any, keyframe: bool = True, timestamp: int | None = None, packet: Any = None,
                    audio: bool = False) -> None:
        """Keep the frame; write out what falls off the window."""
        with self._lock:
            if self.buffer_duration_ms == 0 or not self.recording:
                return
            self._ring.append((bytes(memoryview(frame).cast("B")), keyframe, int(timestamp or 0), packet, audio))
            self._flush(timestamp, self._output)

    def start(self) -> None:
        """Start keeping frames."""
        with self._lock:
            if self.recording:
                raise RuntimeError("Circular output is running")
            self.recording = True

    def stop(self) -> None:
        """Stop; an output still open gets the rest of the ring and is stopped."""
        with self._lock:
            if not self.recording:
                raise RuntimeError("Circular output was not started")
            self.recording = False
            output, self._output = self._output, None
        if output is not None:
            self._flush(None, output)
            output.stop()

    def _add_stream(self, encoder_stream: str, codec_name: str, **kwargs: Any) -> None:
        self._streams.append((encoder_stream, codec_name, kwargs))
