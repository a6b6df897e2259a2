"""H.264 MP4 files that browsers and QuickTime play, written atomically; the one video writer of rollcam.

pip's OpenCV wheels carry no H.264 encoder (their FFmpeg is built without x264 or OpenH264) and write MPEG-4
Part 2 (``mp4v``), which browsers and QuickTime refuse. ``VideoWriter`` pipes raw BGR frames into an ffmpeg
executable instead: the one that the ``imageio-ffmpeg`` package ships (or ``IMAGEIO_FFMPEG_EXE``), encoding with
libx264 (else libopenh264) to yuv420p H.264 in an MP4 whose index sits at the front (``+faststart``), so it
plays while it downloads. ffmpeg runs as its own process, so no GPL code is loaded into rollcam's, in its own
process group, so a terminal's Ctrl-C stops rollcam, which finishes the video, and not ffmpeg.

The file is written under a temporary name beside ``path`` (``.NAME.<token>.part``) and moved into place
durably (fsynced, renamed, directory fsynced: ``rollcam.common.files.commit``) by ``close()``; ``abort()``
(or an exception inside ``with``) removes it, so a half-written video is never left under its final name.
A video that got no frames is not written at all.
"""

from __future__ import annotations

import contextlib
import math
import os
import subprocess
import tempfile
from fractions import Fraction
from functools import lru_cache
from pathlib import Path
from typing import IO

import numpy as np
from rollcam.common.errors import ConfigError, RollcamError, require
from rollcam.common.files import commit, part_path

ENCODERS = ("libx264", "libopenh264")
"""H.264 encoders in order of preference (x264 gives better pictures per bit; OpenH264 is the BSD fallback)."""

X264_PRESET, X264_CRF = "veryfast", 23


def ffmpeg_exe() -> str:
    """The ffmpeg executable: ``IMAGEIO_FFMPEG_EXE`` if set, else the one imageio-ffmpeg ships."""
    return require("imageio_ffmpeg", package="imageio-ffmpeg", feature="writing MP4 video").get_ffmpeg_exe()


@lru_cache(maxsize=4)
def h264_encoder(exe: str) -> str:
    """The best H.264 encoder ``exe`` has; a ``RollcamError`` when it has none."""
    try:
        out = subprocess.run([exe, "-hide_banner", "-encoders"], capture_output=True, text=True, timeout=30,
                             check=False).stdout
    except OSError as exc:
        raise RollcamError(f"cannot run ffmpeg {exe!r}: {exc}") from None
    names = {line.split()[1] for line in out.splitlines() if len(line.split()) > 1 and line.split()[0][:1] == "V"}
    for name in ENCODERS:
        if name in names:
            return name
    raise RollcamError(f"ffmpeg {exe!r} has no H.264 encoder (wanted one of {', '.join(ENCODERS)})")


class VideoWriter:
    """An H.264 (yuv420p) MP4 of BGR frames, ``fps`` frames a second, each ``size`` = (width, height) pixels.

    Odd widths or heights are padded with one black column or row (yuv420p needs even sizes): ``encoded_size``
    is what the file holds. Use as a context manager, or call ``write`` then ``close`` (or ``abort``).
    """

    def __init__(self, path: str | os.PathLike[str], fps: float, size: tuple[int, int]) -> None:
        if not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
            raise ConfigError(f"video frame rate must be a positive number, got {fps!r}")
        if len(size) != 2 or not all(isinstance(v, (int, np.integer)) and v > 0 for v in size):
            raise ConfigError(f"video size must be (width, height) in positive pixels, got {size!r}")
        self.path = Path(path)
        self.part = part_path(self.path)
        self.fps = float(fps)
        self.size = (int(size[0]), int(size[1]))
        self.encoded_size = (self.size[0] + self.size[0] % 2, self.size[1] + self.size[1] % 2)
        self.frames = 0
        exe = ffmpeg_exe()
        self.encoder = h264_encoder(exe)
        rate = Fraction(self.fps).limit_denominator(1001)  # 29.97 -> 30000/1001, 30.0 -> 30
        w, h = self.size
        cmd = [exe, "-hide_banner", "-nostdin", "-loglevel", "error", "-y",
               "-f", "rawvideo", "-pix_fmt", "bgr24", "-s", f"{w}x{h}", "-framerate", str(rate), "-i", "pipe:0",
               "-an", "-c:v", self.encoder, "-pix_fmt", "yuv420p"]
        if self.encoded_size != self.size:
            cmd += ["-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2"]
        if self.encoder == "libx264":
            cmd += ["-preset", X264_PRESET, "-crf", str(X264_CRF)]
        else:  # OpenH264 has no quality scale: about 0.1 bit per pixel
            cmd += ["-b:v", str(max(100_000, int(0.1 * w * h * self.fps)))]
        cmd += ["-movflags", "+faststart", "-f", "mp4", str(self.part)]
        self._log: IO[bytes] = tempfile.TemporaryFile()  # noqa: SIM115 (closed by close/abort); a file, not a pipe, so a chatty ffmpeg cannot block
        try:
            # Its own session (so its own process group): a terminal's Ctrl-C, sent to the whole foreground group,
            # reaches rollcam only, which then closes the pipe so ffmpeg finishes the file. Were ffmpeg in the
            # group too it would die of the same SIGINT and the video would be lost. It still ends when rollcam
            # does, however rollcam ends: its input pipe closes.
            self._proc: subprocess.Popen[bytes] | None = subprocess.Popen(
                cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=self._log, start_new_session=True)
        except OSError as exc:
            self._log.close()
            raise RollcamError(f"cannot run ffmpeg {exe!r}: {exc}") from None

    def __repr__(self) -> str:
        state = "open" if self._proc is not None else "closed"
        return (f"VideoWriter({str(self.path)!r}, {self.fps:g} fps, {self.size[0]}x{self.size[1]}, "
                f"{self.encoder}, {self.frames} frames, {state})")

    def write(self, image: np.ndarray) -> None:
        """Append one frame: an (height, width, 3) uint8 BGR image of the writer's size."""
        if self._proc is None:
            raise RollcamError(f"{self.path} is already closed")
        w, h = self.size
        if image.shape != (h, w, 3) or image.dtype != np.uint8:
            raise ConfigError(f"a frame for {self.path.name} must be ({h}, {w}, 3) uint8 BGR, "
                              f"got {image.shape!r} {image.dtype}")
        try:
            self._proc.stdin.write(np.ascontiguousarray(image).data)  # type: ignore[union-attr]
        except (BrokenPipeError, OSError):
            self.abort()
            raise OSError(f"writing {self.path} failed: {self._error}") from None
        self.frames += 1

    def close(self) -> None:
        """Finish the file and rename it into place (nothing when no frame came); safe to call twice."""
        if self._proc is None:
            return
        if self.frames == 0:
            self.abort()
            return
        proc, self._proc = self._proc, None
        with contextlib.suppress(BrokenPipeError, OSError):
            proc.stdin.close()  # type: ignore[union-attr]
        rc = proc.wait()
        if rc != 0:
            self._proc = proc  # so abort() reads the log and removes the part file
            self.abort()
            raise OSError(f"writing {self.path} failed (ffmpeg exit status {rc}): {self._error}")
        self._log.close()
        commit(self.part, self.path)

    def abort(self) -> None:
        """Stop encoding and remove the unfinished file; safe to call twice, and after close()."""
        proc, self._proc = self._proc, None
        if proc is not None:
            with contextlib.suppress(OSError):
                proc.stdin.close()  # type: ignore[union-attr]
            if proc.poll() is None:
                proc.kill()
            proc.wait()
            self._log.seek(0)
            self._error = self._log.read().decode(errors="replace").strip() or "ffmpeg stopped"
            self._log.close()
        self.part.unlink(missing_ok=True)

    _error = "ffmpeg stopped"

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, exc_type: object, *_: object) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()
