"""Rolling-shutter correction from a gyro: per-line rotational unwarp to one reference instant.

The standard ISP / stabiliser approach: integrate the gyro to the camera's orientation at every line's sample
time, then resample the frame so that every line is seen from the orientation of the reference instant (the
first line's time, the instant a global-shutter frame of the same exposure shows). Each output pixel's ray is
rotated into the camera of the line that saw it, found by a short fixed-point iteration (the line a ray lands
on depends on that line's own rotation), and the image is sampled there (bilinear, ``cv2.remap``). Rotation
only: parallax from camera translation and the motion of objects stay as the rolling shutter made them.

``gyro_line_rotations`` is the integration (camera angular rate = ``R_cam_imu`` times the gyro, at stamp
minus the camera-IMU time offset; orientation by the trapezoid rule between samples, exact for a rate that
is linear between them); ``unwarp`` the resampling; ``correct_image`` both. Pixels whose rays leave the frame
are black, and ``valid`` says which. Intrinsics ``(fx, fy, cx, cy)`` are OpenCV's (and Kalibr's): pixel
centres at integer coordinates (``Frame.meta["intrinsics"]`` of a synthetic frame with an IMU).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange
from rollcam.common.errors import ConfigError

from ._jitcache import guard
from .imu import ImuSamples
from .pose import rotation_vector_to_matrix

FIXED_POINT_STEPS = 4
GRID_PX = 8
"""Spacing of the solved resampling map (interpolated between): the map of a rotation a few degrees a frame
is smooth, so 8 px departs from the per-pixel map by well under 0.01 px (``tests/test_imu.py`` checks it)."""


def gyro_line_rotations(samples: ImuSamples, line_times_ns: np.ndarray, reference_ns: int) -> np.ndarray:
    """Per line, the rotation taking the reference instant's camera rays to that line's camera rays (n, 3, 3).

    ``samples`` must cover every line time and the reference (after the time offset): a ConfigError says
    which instant they miss.
    """
    p = samples.params
    r_ci = p.R_cam_imu
    tau = samples.t_ns.astype(np.int64) - p.time_offset_ns  # camera-clock instants the samples measure
    line_times_ns = np.asarray(line_times_ns, np.int64)
    want = np.concatenate([line_times_ns, [int(reference_ns)]])
    if len(samples) < 2 or want.min() < tau[0] or want.max() > tau[-1]:
        span = f"{tau[0]}..{tau[-1]}" if len(samples) else "none"
        raise ConfigError(f"IMU samples measure camera times {span} ns; the frame needs {want.min()}..{want.max()}")
    omega = samples.gyro @ r_ci.T  # camera-frame angular rates
    dt = np.diff(tau).astype(np.float64) * 1e-9
    steps = rotation_vector_to_matrix(0.5 * (omega[1:] + omega[:-1]) * dt[:, None])
    q = np.empty((len(samples), 3, 3))
    q[0] = np.eye(3)
    for k in range(steps.shape[0]):  # a few samples per frame: a Python loop is cheap
        q[k + 1] = q[k] @ steps[k]
    orient = _orientation_at(q, tau, omega, want)
    ref = orient[-1]
    # line camera <- reference camera: Q(t_line)^T Q(t_ref)
    return np.einsum("nji,jk->nik", orient[:-1], ref)


def _orientation_at(q: np.ndarray, tau: np.ndarray, omega: np.ndarray, t_ns: np.ndarray) -> np.ndarray:
    """Integrated orientations at times ``t_ns`` (inside the samples), the rate linear between samples."""
    k = np.clip(np.searchsorted(tau, t_ns, side="right") - 1, 0, len(tau) - 2)
    h = (t_ns - tau[k]).astype(np.float64) * 1e-9
    span = (tau[k + 1] - tau[k]).astype(np.float64) * 1e-9
    slope = (omega[k + 1] - omega[k]) / span[:, None]
    return q[k] @ rotation_vector_to_matrix(omega[k] * h[:, None] + 0.5 * slope * (h * h)[:, None])


@njit(cache=True, parallel=True)
def _maps(line_rot, fx, fy, cx, cy, by_column, step, map_x, map_y):
    """Source coordinates of output pixels (u, v) = (j * step, i * step) into ``map_x[i, j]``, ``map_y[i, j]``."""
    h, w = map_x.shape
    n = line_rot.shape[0]
    for i in prange(h):
        for j in range(w):
            u, v = j * step, i * step
            dx, dy = (u - cx) / fx, (v - cy) / fy
            line = float(u if by_column else v)
            us, vs = float(u), float(v)
            for _ in range(FIXED_POINT_STEPS):
                lf = min(max(line, 0.0), n - 1.0)
                i0 = min(int(math.floor(lf)), n - 2) if n > 1 else 0
                a = lf - i0 if n > 1 else 0.0
                i1 = i0 + 1 if n > 1 else 0
                r0, r1 = line_rot[i0], line_rot[i1]
                p0 = r0[0, 0] * dx + r0[0, 1] * dy + r0[0, 2]
                p1 = r0[1, 0] * dx + r0[1, 1] * dy + r0[1, 2]
                p2 = r0[2, 0] * dx + r0[2, 1] * dy + r0[2, 2]
                p0 += a * (r1[0, 0] * dx + r1[0, 1] * dy + r1[0, 2] - p0)
                p1 += a * (r1[1, 0] * dx + r1[1, 1] * dy + r1[1, 2] - p1)
                p2 += a * (r1[2, 0] * dx + r1[2, 1] * dy + r1[2, 2] - p2)
                if p2 <= 1e-9:  # behind the camera: no source
                    us, vs = -1e6, -1e6
                    break
                us = fx * p0 / p2 + cx
                vs = fy * p1 / p2 + cy
                line = us if by_column else vs
            map_x[i, j] = us
            map_y[i, j] = vs


@njit(cache=True, parallel=True)
def _upsample(coarse, step, out):
    """Bilinear interpolation of a map sampled every ``step`` pixels (grid point k at pixel k * step)."""
    h, w = out.shape
    for v in prange(h):
        gi = v // step
        fy = (v - gi * step) / step
        gi1 = min(gi + 1, coarse.shape[0] - 1)
        for u in range(w):
            gj = u // step
            fx = (u - gj * step) / step
            gj1 = min(gj + 1, coarse.shape[1] - 1)
            top = coarse[gi, gj] + fx * (coarse[gi, gj1] - coarse[gi, gj])
            bot = coarse[gi1, gj] + fx * (coarse[gi1, gj1] - coarse[gi1, gj])
            out[v, u] = top + fy * (bot - top)


def unwarp(image: np.ndarray, line_rotations: np.ndarray, intrinsics: tuple[float, float, float, float], *,
           by_column: bool = False, grid_px: int = GRID_PX) -> tuple[np.ndarray, np.ndarray]:
    """``image`` seen from the reference orientation: per-line rotations (``gyro_line_rotations``, one per
    row, or per column with ``by_column``) and pinhole ``(fx, fy, cx, cy)``. Returns the image and the mask
    of pixels whose source lies inside the frame. The resampling map is solved every ``grid_px`` pixels and
    interpolated between (1: at every pixel; the map is smooth, see ``GRID_PX``)."""
    import cv2

    h, w = image.shape[:2]
    n_lines = w if by_column else h
    if line_rotations.shape != (n_lines, 3, 3):
        raise ConfigError(f"need one rotation per line: {n_lines} lines, got {line_rotations.shape}")
    fx, fy, cx, cy = (float(v) for v in intrinsics)
    step = int(grid_px)
    if step < 1:
        raise ConfigError(f"grid_px must be a whole number >= 1, got {grid_px!r}")
    gh, gw = -(-(h - 1) // step) + 1, -(-(w - 1) // step) + 1
    coarse_x = np.empty((gh, gw), np.float32)
    coarse_y = np.empty((gh, gw), np.float32)
    _maps(np.ascontiguousarray(line_rotations, np.float64), fx, fy, cx, cy, bool(by_column), step, coarse_x,
          coarse_y)
    if step == 1:
        map_x, map_y = coarse_x, coarse_y
    else:
        map_x = np.empty((h, w), np.float32)
        map_y = np.empty((h, w), np.float32)
        _upsample(coarse_x, step, map_x)
        _upsample(coarse_y, step, map_y)
    out = cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    valid = (map_x >= 0) & (map_x <= w - 1) & (map_y >= 0) & (map_y <= h - 1)
    return out, valid


def correct_image(image: np.ndarray, samples: ImuSamples, line_times_ns: np.ndarray, reference_ns: int,
                  intrinsics: tuple[float, float, float, float], *, by_column: bool = False
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Gyro correction of one frame: ``gyro_line_rotations`` then ``unwarp``."""
    rot = gyro_line_rotations(samples, line_times_ns, reference_ns)
    return unwarp(image, rot, intrinsics, by_column=by_column)


def forward_points(points_xy: np.ndarray, line_rotations: np.ndarray,
                   intrinsics: tuple[float, float, float, float], *, by_column: bool = False) -> np.ndarray:
    """Where RS-image points (pixel coordinates, x right, y down, (n, 2)) land in the corrected image."""
    fx, fy, cx, cy = intrinsics
    pts = np.asarray(points_xy, np.float64)
    n = line_rotations.shape[0]
    line = np.clip(np.round(pts[:, 0] if by_column else pts[:, 1]), 0, n - 1).astype(np.int64)
    d = np.stack([(pts[:, 0] - cx) / fx, (pts[:, 1] - cy) / fy, np.ones(len(pts))], axis=1)
    ref = np.einsum("nji,nj->ni", line_rotations[line], d)  # reference <- line: the transpose
    return np.stack([fx * ref[:, 0] / ref[:, 2] + cx, fy * ref[:, 1] / ref[:, 2] + cy], axis=1)


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
