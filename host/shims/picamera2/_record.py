"""Recording: the part of ``Picamera2`` that feeds encoders (``picamera2.encoders``) with a stream's frames.

Each frame of a started camera goes, after ``pre_callback`` and ``post_callback`` have drawn on it, to every
running encoder of its stream, on the camera's thread, as picamera2 hands requests to its encoders.
"""

from __future__ import annotations

import threading
import time
from typing import Any

from .encoders import Encoder, H264Encoder, MJPEGEncoder, Quality
from .outputs import FfmpegOutput, FileOutput


class RecordMixin:
    """``start_encoder``, ``stop_encoder``, ``encoders``, ``start_recording``, ``stop_recording``,
    ``start_and_record_video``."""

    camera_config: dict[str, Any]
    encode_stream_name: str
    started: bool
    _cam: Any

    def _init_recording(self) -> None:
        self.encode_stream_name = "main"  # the stream encoders take unless told (configure sets it)
        self._encoders: set[Encoder] = set()
        self._encoders_lock = threading.Lock()

    @property
    def encoders(self) -> set[Encoder]:
        """The encoders that take frames."""
        return self._encoders

    @encoders.setter
    def encoders(self, value: Any) -> None:
        if isinstance(value, Encoder):
            self._encoders.add(value)
        elif isinstance(value, set):
            self._encoders.update(value)
        else:
            raise RuntimeError("Must pass Encoder or set of")

    def _encode(self, request: Any) -> None:
        with self._encoders_lock:
            encoders = list(self._encoders)
        for encoder in encoders:
            if encoder.name in request.arrays:
                encoder.encode(encoder.name, request)

    def start_encoder(self, encoder: Encoder | None = None, output: Any = None, pts: Any = None,
                      quality: Quality | None = None, name: str | None = None) -> None:
        """Start ``encoder`` (or the one set in ``encoders``) on stream ``name`` into ``output`` (an Output, or
        a file name for a FileOutput)."""
        if encoder is None:
            if len(self._encoders) > 1:
                raise RuntimeError("Multiple possible encoders, need to pass encoder")
            encoder = next(iter(self._encoders), None)
        if encoder is None:
            raise RuntimeError("No encoder specified")
        if output is not None:
            encoder.output = FileOutput(output, pts=pts) if isinstance(output, str) else output
        streams = self.camera_config
        if not streams:
            raise RuntimeError("Camera has not been configured")
        name = name or self.encode_stream_name
        if streams.get(name) is None:
            raise RuntimeError(f"Encode stream {name} was not defined")
        encoder.name = name
        encoder.width, encoder.height = streams[name]["size"]
        encoder.format, encoder.stride = streams[name]["format"], streams[name]["stride"]
        if encoder.framerate is None:
            encoder.framerate = min(30.0, 1e9 / self._cam.device.frame_interval_ns)
        encoder.start(quality=quality)
        with self._encoders_lock:
            self._encoders.add(encoder)

    def stop_encoder(self, encoders: Any = None) -> None:
        """Stop ``encoders`` (one, a list or set; default all) and drop them."""
        if encoders is None:
            chosen = list(self._encoders)
        elif isinstance(encoders, Encoder):
            chosen = [encoders]
        else:
            chosen = list(encoders)
        with self._encoders_lock:
            for encoder in chosen:
                self._encoders.discard(encoder)
        for encoder in chosen:
            encoder.stop()

    def start_recording(self, encoder: Encoder, output: Any, pts: Any = None, config: Any = None,
                        quality: Quality | None = None, name: str | None = None) -> None:
        """Configure (``config``; 'video' when never configured), start the encoder, start the camera."""
        if not self.camera_config and config is None:
            config = "video"
        if config is not None:
            self.configure(config)
        self.start_encoder(encoder, output, pts=pts, quality=quality, name=name)
        self.start()

    def stop_recording(self) -> None:
        """Stop the camera, then the encoders (their outputs finish their files)."""
        self.stop()
        self.stop_encoder()

    def start_and_record_video(self, output: Any, encoder: Encoder | None = None, config: Any = None,
                               quality: Quality = Quality.MEDIUM, show_preview: bool = False, duration: float = 0,
                               audio: bool = False) -> None:
        """Record to ``output`` (a name: ``.mp4``/``.ts`` through ffmpeg, ``.mjpeg`` as MJPEG, anything else
        raw H.264; or an Output) for ``duration`` seconds (0: until ``stop_recording()``)."""
        if self.started:
            self.stop()
        if not self.camera_config and config is None:
            config = "video"
        if config is not None:
            self.configure(config)
        if isinstance(output, str):
            extension = output.rsplit(".", 1)[-1].lower()
            if encoder is None:
                encoder = MJPEGEncoder() if extension in ("mjpg", "mjpeg") else H264Encoder()
            output = FfmpegOutput(output, audio=audio) if extension in ("mp4", "ts") else FileOutput(output)
        elif encoder is None:
            encoder = H264Encoder()
        self.start_encoder(encoder, output, quality=quality)
        self.start(show_preview=show_preview)
        if duration:
            time.sleep(duration)
            self.stop_recording()
