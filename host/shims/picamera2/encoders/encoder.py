"""``Encoder``: picamera2's encoder base class. It takes the frames of one stream of a recording camera and
hands each output a frame with its timestamp: the frame's ``SensorTimestamp`` (device clock) in us, counted
from the first frame encoded. The base class itself is the "null" encoder: it passes the raw frame on."""

from __future__ import annotations

import enum
import threading
from fractions import Fraction
from typing import Any

from ..outputs import Output

FFMPEG_PIXEL_FORMATS = {"YUV420": "yuv420p", "NV12": "nv12", "NV21": "nv21", "RGB888": "bgr24", "BGR888": "rgb24",
                        "XRGB8888": "bgra", "XBGR8888": "rgba", "YUYV": "yuyv422", "UYVY": "uyvy422",
                        "YVYU": "yvyu422"}
"""ffmpeg's name for each stream format's bytes (the stand-in's buffers carry no row padding)."""


class Quality(enum.Enum):
    """How good an encoder should make the picture when no bitrate or quantiser is given."""

    VERY_LOW = 0
    LOW = 1
    MEDIUM = 2
    HIGH = 3
    VERY_HIGH = 4


class Encoder:
    """Frames of the stream ``name`` to ``output`` (one Output or a list): ``start(quality)``, ``encode``
    (called by the camera for each frame of a recording), ``stop()``."""

    codec = "rawvideo"

    def __init__(self, framerate: float | None = 30) -> None:
        self.width = self.height = self.stride = 0
        self.format: str | None = None
        self._output: list[Output] = []
        self._running = False
        self._name: str | None = None
        self.framerate = framerate
        self.firsttimestamp: int | None = None
        self.frames_encoded = 0
        self.frame_skip_count = 1
        self._skip_count = 0
        self.audio = False
        self.sync_enable = False
        self.sync = threading.Event()
        self._lock = threading.Lock()

    @property
    def running(self) -> bool:
        """True between start() and stop()."""
        return self._running

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of the frames."""
        return self.width, self.height

    @size.setter
    def size(self, value: tuple[int, int]) -> None:
        self.width, self.height = value

    @property
    def output(self) -> Any:
        """Where frames go: the Output, or the list of them when there are several (as picamera2's)."""
        return self._output[0] if len(self._output) == 1 else self._output

    @output.setter
    def output(self, value: Any) -> None:
        outputs = value if isinstance(value, list) else [value]
        if not all(isinstance(o, Output) for o in outputs):
            raise RuntimeError("Must pass Output")
        added = [out for out in outputs if out not in self._output]
        for out in added:
            if self._running:
                self._send_streams(out)
        self._output = outputs
        if self._running and added:
            self._output_added()

    @property
    def name(self) -> str | None:
        """The stream encoded (``main``, ``lores``)."""
        return self._name

    @name.setter
    def name(self, value: str) -> None:
        if not isinstance(value, str):
            raise RuntimeError("Name must be string")
        self._name = value

    def encode(self, stream: Any, request: Any) -> None:
        """Encode the frame of ``stream`` (a name) in ``request`` (every ``frame_skip_count``-th one)."""
        if self.sync_enable:
            self.sync_enable = False
            self.sync.set()
        if self._skip_count == 0:
            with self._lock:
                if not self._running:
                    return
                name = stream if isinstance(stream, str) else self._name
                self._encode(request.arrays[name], self._timestamp(request))
        self._skip_count = (self._skip_count + 1) % self.frame_skip_count
        self.frames_encoded += 1

    def _encode(self, array: Any, timestamp_us: int) -> None:
        self.outputframe(memoryview(array.reshape(-1)), keyframe=True, timestamp=timestamp_us)

    def _timestamp(self, request: Any) -> int:
        ts = int(request.metadata["SensorTimestamp"])
        if self.firsttimestamp is None:
            self.firsttimestamp = ts
        return (ts - self.firsttimestamp) // 1000

    def _send_streams(self, output: Output) -> None:
        rate = Fraction(1_000_000, round(1_000_000 / self.framerate)) if self.framerate else None
        output._add_stream("video", self.codec, pix_fmt=FFMPEG_PIXEL_FORMATS.get(self.format or ""), rate=rate,
                           width=self.width, height=self.height)

    def start(self, quality: Quality | None = None) -> None:
        """Start the outputs and the encoder."""
        with self._lock:
            if self._running:
                raise RuntimeError("Encoder already running")
            self.frames_encoded, self.firsttimestamp, self._skip_count = 0, None, 0
            self._setup(quality)
            for out in self._output:
                self._send_streams(out)
                out.start()
            self._start()
            self._running = True

    def stop(self) -> None:
        """Finish the frames in flight, then stop the outputs."""
        with self._lock:
            if not self._running:
                raise RuntimeError("Encoder already stopped")
            self._running = False
            self._stop()
        for out in self._output:
            out.stop()

    def outputframe(self, frame: Any, keyframe: bool = True, timestamp: int | None = None, packet: Any = None,
                    audio: bool = False) -> None:
        """Hand a frame to every output."""
        for out in self._output:
            out.outputframe(frame, keyframe, timestamp, packet, audio)

    def _output_added(self) -> None:
        """An output was attached while running (it will take frames from a keyframe on)."""

    def _setup(self, quality: Quality | None) -> None:
        """Choose settings from ``quality`` where none were given."""

    def _start(self) -> None:
        """Start the encoding machinery."""

    def _stop(self) -> None:
        """Finish encoding."""
