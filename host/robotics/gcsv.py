"""An H.264 video with Gyroflow's ``.gcsv`` gyro log beside it (format version 1.3), for stabilising RS footage.

Gyroflow finds ``NAME.gcsv`` beside ``NAME.mp4`` (a sidecar file). The format, as Gyroflow's documentation
defines it (docs.gyroflow.xyz, "GCSV format", and telemetry-parser's reader): a first line ``GYROFLOW IMU LOG``,
then ``key,value`` lines (``version``, ``id``, ``orientation`` mandatory, in that order; the optional metadata;
``tscale``, ``gscale``, ``ascale``), then ``t,gx,gy,gz,ax,ay,az`` and one row per sample, where ``t x tscale`` is
seconds, ``g x gscale`` rad/s and ``a x ascale`` g. rollcam writes:

- ``t`` in integer nanoseconds (``tscale`` 1e-9) on the video's clock: the device stamp minus the device instant
  that the video's first frame (presentation time 0) shows, taken as the middle of its readout (the first line's
  sample time plus half the readout), which is where Gyroflow puts a frame's time when it corrects the rolling
  shutter (its rows at ``frame time + (row - height / 2) x readout / height``). The log starts at the first
  sample at or after that instant: Gyroflow's reader (telemetry-parser) times a ``.gcsv`` from its first row,
  so an earlier row would shift every sample by its lead (the first half frame's rows, read before time 0,
  take the first sample's rate; the first row is at most one sample period after 0). The IMU's own time offset
  (``imu_offset_us``, Kalibr's ``timeshift_cam_imu``) stays in the stamps, as a real logger's would: Gyroflow's
  synchronisation finds it.
- gyro and accelerometer as floats in camera axes (``gscale`` and ``ascale`` 1: rad/s and g, with g = 9.80665
  m/s^2); the IMU's mounting rotation ``R_cam_imu`` is applied to both, so they stay aligned as the format asks.
- ``orientation`` ``yxz``: Gyroflow's reader makes its axis i from the logged axis named by letter i, lower case
  negated; Gyroflow's reference axes for a level camera looking forward are x up, y left, z backwards, which in
  rollcam's camera axes (x right, y down, z forward) are -y, -x, -z.
- ``frame_readout_time``: the active readout in milliseconds, lines x line time, with no blanking (the time
  from the first line's sample to one line time after the last's); ``frame_readout_direction`` 0 top to
  bottom, 1 bottom to top, 2 left to right, 3 right to left (Gyroflow corrects 0 and 1).

Gyroflow's reader looks for the header fields in the file's first 500 bytes, so the header is kept short.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.common.files import write_atomic
from rollcam.sim.frame import Frame
from rollcam.sim.imu import ImuSamples
from rollcam.sim.timing import Readout

from ..recording.imagefiles import image_array
from ..recording.video import VideoWriter
from .messages import readout_lines

GCSV_VERSION = "1.3"
STANDARD_GRAVITY = 9.80665
"""m/s^2 in one g: the unit of ``ascale``."""
ORIENTATION = "yxz"
"""Gyroflow's IMU orientation string for samples in rollcam's camera axes (see the module docstring)."""
READOUT_DIRECTION = {Readout.TOP_TO_BOTTOM: 0, Readout.BOTTOM_TO_TOP: 1, Readout.LEFT_TO_RIGHT: 2,
                     Readout.RIGHT_TO_LEFT: 3}
"""``frame_readout_direction`` codes as Gyroflow's gcsv documentation numbers them."""
HEADER_LIMIT = 500
"""Bytes of the file's start in which Gyroflow's reader looks for the header fields."""
VIDEO_NAME, GCSV_NAME = "capture.mp4", "capture.gcsv"


def readout_ms(frame: Frame) -> float:
    """The active readout of ``frame`` in ms: lines x line time, no blanking (0 for a global shutter)."""
    return readout_lines(frame) * int(frame.line_time_ns) / 1e6


def video_origin_ns(frame: Frame) -> int:
    """The device instant the video's first frame shows: the middle of its readout (see the module docstring)."""
    first = int(frame.timestamp_ns + frame.exposure_ns // 2) if frame.row_times_ns is None \
        else int(np.min(frame.row_times_ns))
    return first + readout_lines(frame) * int(frame.line_time_ns) // 2


def gcsv_header(frame: Frame, video_name: str, *, camera_id: str = "rollcam", timestamp_s: int | None = None,
                note: str = "rollcam emulated camera") -> str:
    """The header block, up to and including the ``t,gx,gy,gz,ax,ay,az`` line."""
    lines = ["GYROFLOW IMU LOG", f"version,{GCSV_VERSION}", f"id,{camera_id}", f"orientation,{ORIENTATION}",
             f"note,{note}", "vendor,rollcam", f"videofilename,{video_name}"]
    if timestamp_s is not None:
        lines.append(f"timestamp,{int(timestamp_s)}")
    if frame.shutter == "rolling" and frame.line_time_ns:
        lines += [f"frame_readout_time,{readout_ms(frame):.6f}",
                  f"frame_readout_direction,{READOUT_DIRECTION[frame.readout]}"]
    lines += ["tscale,0.000000001", "gscale,1", "ascale,1", "t,gx,gy,gz,ax,ay,az"]
    text = "".join(line + "\n" for line in lines)
    if len(text.encode()) > HEADER_LIMIT:
        raise ConfigError(f"the .gcsv header is {len(text.encode())} bytes; Gyroflow reads only the first "
                          f"{HEADER_LIMIT} (shorten the id or note)")
    return text


def gcsv_rows(samples: ImuSamples, origin_ns: int) -> str:
    """The rows of the samples stamped at or after ``origin_ns``: ``t`` in ns from it, gyro (rad/s) and
    accelerometer (g) in camera axes (see the module docstring for why none before it)."""
    r = samples.params.R_cam_imu
    gyro = samples.gyro @ r.T
    accel = samples.accel @ r.T / STANDARD_GRAVITY
    return "".join(f"{t - origin_ns},{g[0]:.9g},{g[1]:.9g},{g[2]:.9g},{a[0]:.9g},{a[1]:.9g},{a[2]:.9g}\n"
                   for t, g, a in zip(samples.t_ns.tolist(), gyro, accel, strict=True) if t >= origin_ns)


def video_image(frame: Frame) -> np.ndarray:
    """The frame as the 8-bit BGR picture the video holds (GREY as grey BGR); other formats are refused."""
    if frame.format not in ("BGR3", "RGB3", "GREY"):
        raise ConfigError(f"--format mp4 takes picture frames (BGR3, RGB3, GREY), not {frame.format.strip()!r}; "
                          "capture raw streams as png or npy")
    from rollcam.sim.codecs import codec  # lazily, as the image files do: importing the capture stays light

    img = image_array(frame, "png")
    return codec("GREY").preview(img, img.shape[1], img.shape[0]) if img.ndim == 2 else img


def check_frames(frames: Sequence[Frame]) -> None:
    """Refuse, before anything is written, what one video cannot hold (a GS/RS pair, non-picture formats)."""
    if len(frames) > 1:
        raise ConfigError("--format mp4 records one stream; leave out --shutter both")
    for frame in frames:
        video_image(frame)


class VideoWithGyro:
    """``capture.mp4`` (H.264, ``fps``) and, when the frames carry IMU samples, ``capture.gcsv`` beside it.

    The video is written as ``rollcam.host.recording.video.VideoWriter`` writes it (temporary name, moved into place
    when finished); the gcsv rows are kept and written atomically after the video is in place, so each file
    is whole or absent. The same interface as the capture's other writers: ``write``, ``close``, ``abort``.
    """

    def __init__(self, out_dir: str | Path, fps: float | None, *, timestamp_s: int | None = None) -> None:
        if not fps or not math.isfinite(fps) or fps <= 0:
            raise ConfigError("--format mp4 needs the source's frame rate; this source reports none")
        self.out_dir, self.fps, self.timestamp_s = Path(out_dir), float(fps), timestamp_s
        self.video_path, self.gcsv_path = self.out_dir / VIDEO_NAME, self.out_dir / GCSV_NAME
        self.frames = self.images = 0
        self._video: VideoWriter | None = None
        self._header: str | None = None
        self._origin_ns = 0
        self._rows: list[str] = []
        self._last_seq: int | None = None
        self._closed = False

    def write(self, frames: Sequence[Frame]) -> None:
        """Append one instant's frame to the video and its IMU samples to the log."""
        if self._closed:
            raise ValueError("video is closed")
        check_frames(frames)
        frame = frames[0]
        img = video_image(frame)
        if self._video is None:
            self._video = VideoWriter(self.video_path, self.fps, (img.shape[1], img.shape[0]))
            self._origin_ns = video_origin_ns(frame)
            self._header = gcsv_header(frame, VIDEO_NAME, timestamp_s=self.timestamp_s)
        self._video.write(img)
        if frame.imu is not None and frame.sequence != self._last_seq:
            self._rows.append(gcsv_rows(frame.imu, self._origin_ns))
            self._last_seq = frame.sequence
        self.frames += 1
        self.images += 1

    def close(self) -> None:
        """Finish the video, then write the log beside it; safe to call twice."""
        if self._closed:
            return
        self._closed = True
        if self._video is None:
            return
        self._video.close()
        if self._rows and self._header is not None:
            write_atomic(self.gcsv_path, (self._header + "".join(self._rows)).encode())

    def abort(self) -> None:
        """Remove the unfinished video; safe to call twice."""
        self._closed = True
        if self._video is not None:
            self._video.abort()
