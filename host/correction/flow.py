"""Flow-based rolling-shutter correction, for object motion: an optional, approximate alternative to the gyro.

The gyro knows only the camera's rotation; a walker's skew is the walker's own motion and no IMU sees it. This
stage estimates every pixel's image velocity from dense optical flow between the previous frame and this one
(OpenCV's DIS, on grey levels) and moves each pixel back along its velocity by its line's time offset from the
reference instant (the first line's, as the gyro correction and the GS frame of the same exposure use):

    x(t_ref) = x - v(x) * (t_line(x) - t_ref),   v(x) = -B(x) / (t(x) - t_prev(x + B(x)))

with ``B`` the flow from this frame to the previous (this frame's pixel x was at x + B in the previous one,
seen at that line's time there), so ``v`` is exact for motion at constant image velocity between the two
frames, whatever lines the point crossed. The output is a backward remap: each output pixel solves
``x = y + v(x) tau(x)`` by a short fixed-point iteration (as ``rollcam.sim.rscorrect`` solves its rays).

What it assumes, and so where it hurts: constant image velocity over a frame period (a drone's 60 Hz
vibration between 30 fps frames aliases, so the flow measures the wrong velocity), flow that is right
(textureless regions, occlusion and disocclusion edges, motion blur, large displacements), and a previous
frame (the first frame of a stream passes unchanged). It corrects camera motion as well as object motion,
as image motion, but with the flow's errors where the gyro's rotation is exact.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.sim.codecs import grey_u8
from rollcam.sim.frame import Frame

FIXED_POINT_STEPS = 4


def dense_flow(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Dense flow (h, w, 2) float32 with ``src(x) ~ dst(x + flow(x))`` (DIS, medium preset, 8-bit images)."""
    import cv2

    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    return dis.calc(grey_u8(src), grey_u8(dst), None)


def _line_time(times: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Line times (ns after the first image line's, float32) at fractional line coordinates, clipped to the
    frame: line offsets are linear in the line index (to the ns), so a slope is enough."""
    n = times.size
    slope = (float(times[-1]) - float(times[0])) / (n - 1) if n > 1 else 0.0
    return np.clip(line, 0.0, n - 1.0).astype(np.float32) * np.float32(slope)


def image_velocity(flow_to_prev: np.ndarray, line_times_ns: np.ndarray, prev_line_times_ns: np.ndarray, *,
                   by_column: bool = False) -> np.ndarray:
    """Per-pixel image velocity (px/ns, (h, w, 2)) from the flow to the previous frame and both frames' line
    sample times (image order)."""
    h, w = flow_to_prev.shape[:2]
    idx = np.arange(w if by_column else h, dtype=np.float32)
    line = idx[None, :] if by_column else idx[:, None]
    prev_line = line + flow_to_prev[..., 0 if by_column else 1]
    base = np.float32(float(line_times_ns[0]) - float(prev_line_times_ns[0]))
    dt = _line_time(line_times_ns, line) - _line_time(prev_line_times_ns, prev_line) + base
    if not np.all(dt > 0):
        raise ConfigError("the previous frame's lines must be sampled before this frame's")
    return -flow_to_prev / dt[..., None]


def unwarp_flow(image: np.ndarray, velocity: np.ndarray, line_times_ns: np.ndarray, reference_ns: int, *,
                by_column: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``image`` with every pixel moved back along ``velocity`` (px/ns) to ``reference_ns``; returns the image
    and the mask of pixels whose source lies inside the frame."""
    import cv2

    h, w = image.shape[:2]
    times = np.asarray(line_times_ns, np.int64)
    if times.shape != ((w if by_column else h),):
        raise ConfigError(f"need one time per line: {w if by_column else h} lines, got {times.shape}")
    if velocity.shape != (h, w, 2):
        raise ConfigError(f"velocity must be ({h}, {w}, 2), got {velocity.shape}")
    u, v = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    rel = np.float32(float(times[0]) - float(reference_ns))
    vel = np.ascontiguousarray(velocity, np.float32)
    mx, my = u, v
    for _ in range(FIXED_POINT_STEPS):
        tau = _line_time(times, mx if by_column else my) + rel
        s = cv2.remap(vel, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        mx, my = u + s[..., 0] * tau, v + s[..., 1] * tau
    out = cv2.remap(image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    valid = (mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1)
    return out, valid


def flow_correct(prev: np.ndarray, image: np.ndarray, line_times_ns: np.ndarray, prev_line_times_ns: np.ndarray,
                 reference_ns: int, *, by_column: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Flow correction of one frame from the frame before it (8-bit images, line times in image order)."""
    velocity = image_velocity(dense_flow(image, prev), np.asarray(line_times_ns, np.int64),
                              np.asarray(prev_line_times_ns, np.int64), by_column=by_column)
    return unwarp_flow(image, velocity, line_times_ns, reference_ns, by_column=by_column)


class FlowCorrector:
    """Corrects the frames of one stream in order from each frame and the one before it (``rollcam detect
    --correct flow``); the first frame, and a global-shutter one, pass unchanged."""

    def __init__(self) -> None:
        self._prev: tuple[np.ndarray, np.ndarray] | None = None
        self.frames = 0

    def correct(self, frame: Frame) -> Frame:
        """``frame`` moved to its first line's instant (BGR), or unchanged (see the class docstring)."""
        from ..preview import frame_bgr

        if frame.row_times_ns is None:
            raise ConfigError(f"flow correction needs line times; frame {frame.sequence} has none")
        bgr = frame_bgr(frame)
        prev, self._prev = self._prev, (bgr, frame.row_times_ns)
        if prev is None or frame.shutter != "rolling" or frame.line_time_ns == 0 or prev[0].shape != bgr.shape:
            return frame
        times = frame.row_times_ns
        image, _ = flow_correct(prev[0], bgr, times, prev[1], int(times.min()), by_column=frame.readout.by_column)
        self.frames += 1
        return dataclasses.replace(frame, data=image, format="BGR3", meta={**frame.meta, "rs_correct": "flow-host"})
