"""``H264Encoder``: H.264 by ffmpeg (libx264, else OpenH264), run as its own program, as rollcam's videos are.

Raw frames of the stream go into ffmpeg's standard input; its output is the H.264 byte stream with an access
unit delimiter before each frame, split here into frames. ffmpeg makes no B-frames, so its frames come out in
the order they went in and each takes the timestamp of its raw frame (the device clock's, in us from the
first frame). On a Pi this is the hardware encoder (``LibavH264Encoder`` on a Pi 5; both names are here).
"""

from __future__ import annotations

import collections
import contextlib
import itertools
import logging
import os
import re
import subprocess
import threading
from typing import Any

from rollcam.host.recording.video import ffmpeg_exe, h264_encoder

from .encoder import FFMPEG_PIXEL_FORMATS, Encoder, Quality

_log = logging.getLogger("picamera2")
_AUD = re.compile(b"\\x00\\x00\\x00\\x01\\x09")
_NAL_START = re.compile(b"\\x00\\x00\\x01(.)", re.S)
_MBPS_1080P30 = {Quality.VERY_LOW: 2, Quality.LOW: 4, Quality.MEDIUM: 6, Quality.HIGH: 9, Quality.VERY_HIGH: 15}
"""picamera2's bitrates (Mbit/s) for each Quality at 1080p30, scaled by pixels a second for other streams."""


def split_access_units(data: bytes) -> tuple[list[bytes], bytes]:
    """Complete access units (each from one delimiter to the next) in an H.264 byte stream, and the rest."""
    starts = [m.start() for m in _AUD.finditer(data)]
    units = [data[a:b] for a, b in itertools.pairwise(starts)]
    return units, data[starts[-1]:] if starts else data


def is_idr(unit: bytes) -> bool:
    """True when the access unit holds an IDR slice (a keyframe)."""
    return any(m.group(1)[0] & 0x1F == 5 for m in _NAL_START.finditer(unit))


class H264Encoder(Encoder):
    """H.264 at ``bitrate`` (bit/s), or quantiser ``qp``, or a Quality (picamera2's bitrate for it); an IDR
    frame every ``iperiod`` frames (30, as picamera2's software encoder; 0 or None: the first only) and when
    asked (``force_key_frame``); ``repeat``: SPS and PPS before every IDR frame (a stream a client may join, or
    an output be attached, at any keyframe)."""

    codec = "h264"

    def __init__(self, bitrate: int | None = None, repeat: bool = True, iperiod: int | None = 30,
                 framerate: float | None = None, enable_sps_framerate: bool = False, qp: int | None = None,
                 profile: str | None = None) -> None:
        super().__init__(framerate=framerate)
        self._bitrate = bitrate
        self.repeat, self.iperiod, self.qp, self.profile = repeat, iperiod, qp, profile
        self._proc: subprocess.Popen[bytes] | None = None
        self._reader: threading.Thread | None = None
        self._stamps: collections.deque[int] = collections.deque()
        self._failed = False
        self._keyframe_wanted = False

    @property
    def bitrate(self) -> int | None:
        """Bits a second (None: the quantiser ``qp`` decides)."""
        return self._bitrate

    @bitrate.setter
    def bitrate(self, value: int | None) -> None:
        self._bitrate = value

    def _setup(self, quality: Quality | None) -> None:
        # As picamera2: a Quality given, or neither bitrate nor qp set, picks the bitrate.
        if quality is not None or (self._bitrate is None and self.qp is None):
            quality = Quality.MEDIUM if quality is None else quality
            pixels_per_s = self.width * self.height * (self.framerate or 30)
            self._bitrate = int(_MBPS_1080P30[quality] * 1_000_000 * pixels_per_s / (1920 * 1080 * 30))

    def force_key_frame(self) -> None:
        """Make the next frame a keyframe."""
        self._keyframe_wanted = True

    def command(self) -> list[str]:
        """The ffmpeg command line for this stream and these settings."""
        pix_fmt = FFMPEG_PIXEL_FORMATS.get(self.format or "")
        if pix_fmt is None:
            raise RuntimeError(f"Format {self.format} not supported by the H.264 encoder")
        exe = ffmpeg_exe()
        codec = h264_encoder(exe)
        rate = self.framerate or 30
        cmd = [exe, "-hide_banner", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", pix_fmt,
               "-s", f"{self.width}x{self.height}", "-r", f"{rate:g}", "-i", "pipe:0", "-c:v", codec,
               "-pix_fmt", "yuv420p", "-bf", "0"]
        if codec == "libx264":
            cmd += ["-preset", "veryfast", "-tune", "zerolatency"]
            if self.repeat:
                cmd += ["-x264-params", "repeat-headers=1"]
        if self._bitrate:
            cmd += ["-b:v", str(int(self._bitrate))]
        elif self.qp is not None:
            cmd += ["-qp", str(int(self.qp))] if codec == "libx264" else ["-qmin", str(self.qp), "-qmax", str(self.qp)]
        cmd += ["-g", str(int(self.iperiod) if self.iperiod else (1 << 31) - 1)]
        if self.profile:
            cmd += ["-profile:v", str(self.profile).lower()]
        return [*cmd, "-bsf:v", "h264_metadata=aud=insert", "-f", "h264", "pipe:1"]

    def _start(self) -> None:
        self._stamps.clear()
        self._failed = False
        self._proc = subprocess.Popen(self.command(), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                      stderr=subprocess.PIPE)
        self._reader = threading.Thread(target=self._read, args=(self._proc,), name="picamera2-h264", daemon=True)
        self._reader.start()

    def _output_added(self) -> None:
        # The new output waits for a keyframe: make the next frame one (a Pi's encoder would make one within
        # iperiod frames, a second at most; this machine may deliver far fewer frames a second).
        self.force_key_frame()

    def _encode(self, array: Any, timestamp_us: int) -> None:
        if self._keyframe_wanted:  # a fresh ffmpeg starts with an IDR frame; the old one finishes its frames
            self._keyframe_wanted = False
            self._stop()
            self._start()
        proc = self._proc
        if proc is None or self._failed:
            return
        self._stamps.append(timestamp_us)
        try:
            proc.stdin.write(memoryview(array.reshape(-1)))
        except OSError as exc:
            self._failed = True
            _log.error("the H.264 encoder (ffmpeg) stopped taking frames: %s", exc)

    def _read(self, proc: subprocess.Popen[bytes]) -> None:
        pending = b""
        fd = proc.stdout.fileno()
        while chunk := os.read(fd, 1 << 16):
            units, pending = split_access_units(pending + chunk)
            for unit in units:
                self._emit(unit)
        if pending:
            self._emit(pending)

    def _emit(self, unit: bytes) -> None:
        stamp = self._stamps.popleft() if self._stamps else None
        self.outputframe(unit, keyframe=is_idr(unit), timestamp=stamp)

    def _stop(self) -> None:
        proc, self._proc = self._proc, None
        if proc is None:
            return
        with contextlib.suppress(OSError):
            proc.stdin.close()
        if self._reader is not None:
            self._reader.join()
        err = proc.stderr.read()
        proc.wait()
        if proc.returncode:
            _log.error("the H.264 encoder (ffmpeg) exited %s: %s", proc.returncode,
                       err.decode(errors="replace").strip()[-500:])


LibavH264Encoder = H264Encoder
