"""``FfmpegOutput``: encoded frames muxed by ffmpeg, run as its own program, into an MP4, a TS, a stream...

picamera2's ``FfmpegOutput`` pipes the bare H.264 stream into ffmpeg, which stamps each frame with the wall
clock as it arrives. Here each frame goes in with its own timestamp, the device clock's (the frame's
``SensorTimestamp``, counted from the recording's first frame): the stream reaches ffmpeg as IVF, a container
of one 12-byte header per frame (size, pts in us) that ffmpeg reads for any codec with a fourcc, and ffmpeg
copies the frames into the container the output names, without encoding them again.
"""

from __future__ import annotations

import contextlib
import logging
import shlex
import struct
import subprocess
import threading
from typing import Any

from rollcam.host.recording.video import ffmpeg_exe

from .output import Output

_log = logging.getLogger("picamera2")
_FOURCC = {"h264": b"H264", "mjpeg": b"MJPG"}


def ivf_header(fourcc: bytes, width: int, height: int) -> bytes:
    """An IVF file header: ``fourcc``, size, a time base of 1 us, frame count unknown (0)."""
    return b"DKIF" + struct.pack("<HH4sHHIIII", 0, 32, fourcc, width, height, 1_000_000, 1, 0, 0)


def ivf_frame(frame: Any, pts_us: int) -> bytes:
    """One IVF frame: its size and pts (us), then its bytes."""
    data = bytes(memoryview(frame).cast("B"))
    return struct.pack("<IQ", len(data), pts_us) + data


class FfmpegOutput(Output):
    """Frames into ``ffmpeg ... <output_filename>`` (a file name such as ``video.mp4``, or ffmpeg's output
    options and URL, as picamera2's: ``"-f mpegts udp://host:port"``). Audio is not recorded (no microphone)."""

    def __init__(self, output_filename: str, audio: bool = False, audio_device: str = "default",
                 audio_sync: int = -300000, audio_samplerate: int = 48000, audio_codec: str = "aac",
                 audio_bitrate: int = 128000, pts: Any = None, audio_filter: Any = None) -> None:
        super().__init__(pts=pts)
        self.output_filename = output_filename
        self.audio = audio
        self.ffmpeg: subprocess.Popen[bytes] | None = None
        self.error_callback: Any = None  # called with the error when ffmpeg stops taking frames
        self._stopping = False
        self._last_pts = -1

    def start(self) -> None:
        """Start ffmpeg (it gets the stream's header with the first frame)."""
        if self.audio:
            _log.warning("rollcam's picamera2 stand-in records no audio (there is no microphone)")
        command = [ffmpeg_exe(), "-hide_banner", "-loglevel", "error", "-y", "-f", "ivf", "-i", "pipe:0",
                   "-c:v", "copy", *shlex.split(self.output_filename)]
        self.ffmpeg = subprocess.Popen(command, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
        self._started_stream = False
        self._last_pts = -1
        self._stopping = False
        super().start()
        threading.Thread(target=self._watch, args=(self.ffmpeg,), name="picamera2-ffmpeg", daemon=True).start()

    def _watch(self, proc: subprocess.Popen[bytes]) -> None:
        """Tell ``error_callback`` at once when ffmpeg ends on its own (its destination went away)."""
        proc.wait()
        if not self._stopping and self.ffmpeg is proc and self.error_callback is not None:
            self.error_callback(RuntimeError(f"ffmpeg for {self.output_filename!r} exited {proc.returncode}"))

    def stop(self) -> None:
        """Close ffmpeg's input and wait for it to finish the file."""
        self._stopping = True
        super().stop()
        proc, self.ffmpeg = self.ffmpeg, None
        if proc is None:
            return
        with contextlib.suppress(OSError):
            proc.stdin.close()
        err = proc.stderr.read()  # ends when ffmpeg exits, having written the file
        proc.wait()
        if proc.returncode:
            _log.error("ffmpeg for %r exited %s: %s", self.output_filename, proc.returncode,
                       err.decode(errors="replace").strip()[-500:])

    def outputframe(self, frame: Any, keyframe: bool = True, timestamp: int | None = None, packet: Any = None,
                    audio: bool = False) -> None:
        """Pass one frame to ffmpeg with its timestamp (us)."""
        proc = self.ffmpeg
        if audio or proc is None or not self.recording:
            return
        if not self._started_stream:
            if not keyframe:
                return
            codec = self.stream.get("codec") or ("mjpeg" if bytes(frame[:2]) == b"\xff\xd8" else "h264")
            header = ivf_header(_FOURCC.get(codec, b"H264"), int(self.stream.get("width", 0)),
                                int(self.stream.get("height", 0)))
            self._started_stream = True
        else:
            header = b""
        pts = max(int(timestamp or 0), self._last_pts + 1)  # strictly increasing, as a container needs
        self._last_pts = pts
        try:
            proc.stdin.write(header + ivf_frame(frame, pts))
            proc.stdin.flush()
        except (BrokenPipeError, OSError) as exc:
            if self.error_callback is None:
                raise RuntimeError(f"ffmpeg for {self.output_filename!r} stopped taking frames: {exc}") from exc
            self.error_callback(exc)
        self.outputtimestamp(timestamp)


class PyavOutput(FfmpegOutput):
    """picamera2's PyAV output (a file or URL in any container, ``format`` naming it when the name does not),
    here muxed by ffmpeg the same way as ``FfmpegOutput``."""

    def __init__(self, output_name: str, format: str | None = None, pts: Any = None,
                 options: dict[str, str] | None = None) -> None:
        args = ["-f", format] if format else []
        for key, value in (options or {}).items():
            args += [f"-{key}", str(value)]
        super().__init__(shlex.join([*args, output_name]), pts=pts)
