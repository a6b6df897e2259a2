"""Numba kernels of a moving camera's background blur: the static world integrated along each pixel's image path.

Under ego-motion the static background's image motion during a line's exposure is known in closed form: the
camera pose at every instant, and the plane each pixel's ray hits (the street's ground plane z = 0, its two facade
planes, or the sky at infinity; ``rollcam_shade.c`` reports which). Through its plane, the ray of pixel p at time
t meets the world at a point that the line's mid-exposure pose sees at ``H_t p`` (a homography per line, time and
plane). So a line's exposure integral of the background is the mean, over the line's time samples, of one render
of the background (each line at its mid-exposure pose, ``background_frame``, with margins for what moves into
view) read at ``H_t p`` (``path_blur``): one shading of each pixel, then cheap bilinear reads, instead of one
shading of the whole line per time sample. What the plane mapping misses is where the surface changes between p
and ``H_t p`` (a roof edge against the sky): the error is stated and tested against the many-sample reference
(``tests/test_sensor_path.py``).

The render is a rolling-shutter one (each line at its own time), so a read from line L sees the world
``(L - l) * lt`` later than line l's mid-exposure: ``path_blur`` moves the read along the pixel's image velocity
by that much (first order in the line time; exact for a global shutter, whose lt is 0).

Used by ``paint.Painter.path_blur``; render space as in ``lines`` (lines are rows of
the render buffer; a column readout renders the camera transposed).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .._jitcache import guard
from .shader import SURF_EAST, SURF_GROUND, SURF_SKY, SURF_WEST, path_reads_c
from .world import C_CX, C_CY, C_FX, C_FY, C_TRANSPOSED, W_FACADE, background_span

N_SURFACES = 4
"""Planes a background pixel's ray can hit (``SURF_*``: sky, ground, west facade, east facade)."""


@njit(cache=True)
def _background_rows(world, lut_b, bld, light, cam, rot_tab, pos_tab, margin, out, surface, e0, e1):
    n_along = out.shape[1] - 2 * margin
    for e in range(e0, e1):
        background_span(world, lut_b, bld, light, cam, rot_tab[e], pos_tab[e], float(e - margin), -margin,
                        n_along + margin, out[e], surface[e])


@njit(cache=True, nogil=True)
def background_frame(world, lut_b, bld, light, cam, rot_tab, pos_tab, margin, out, surface):
    """The background (no actors) of render lines ``-margin .. n + margin - 1``, line ``e - margin`` at pose
    ``e`` of (rot_tab, pos_tab), pixels ``-margin .. n_along + margin - 1``, into ``out`` (float32) and each
    pixel's surface into ``surface`` (int8): buffers of ``(n + 2 margin, n_along + 2 margin[, 3])``."""
    _background_rows(world, lut_b, bld, light, cam, rot_tab, pos_tab, margin, out, surface, 0, out.shape[0])


@njit(cache=True, parallel=True, nogil=True)
def background_frame_par(world, lut_b, bld, light, cam, rot_tab, pos_tab, margin, out, surface):
    """``background_frame`` over the numba threads (interleaved blocks of 8 lines)."""
    n = out.shape[0]
    n_blocks = (n + 7) // 8
    for b in prange(n_blocks):
        _background_rows(world, lut_b, bld, light, cam, rot_tab, pos_tab, margin, out, surface, 8 * b,
                         min(8 * b + 8, n))


def plane_homographies(rot_mid: np.ndarray, pos_mid: np.ndarray, rot_t: np.ndarray, pos_t: np.ndarray,
                       facade_x_m: float) -> np.ndarray:
    """``(lines, times, N_SURFACES, 3, 3)`` maps from a camera ray at pose t to the mid pose's ray of the same
    world point on each surface's plane: ``R_m (I + (c_t - c_m) n^T / (d - n . c_t)) R_t^T`` for the plane
    ``n . X = d`` (``R_m R_t^T`` for the sky, at infinity).

    ``rot_mid``/``pos_mid``: ``(lines, 3, 3)`` / ``(lines, 3)`` world-to-camera rotation and camera position at
    each line's mid-exposure; ``rot_t``/``pos_t``: ``(lines, times, ...)`` at its sample times.
    """
    rel = np.einsum("lij,ltkj->ltik", rot_mid, rot_t)  # R_m R_t^T
    out = np.empty((*rel.shape[:2], N_SURFACES, 3, 3))
    out[:, :, SURF_SKY] = rel
    shift = pos_t - pos_mid[:, None, :]  # c_t - c_m, world
    planes = {SURF_GROUND: (2, 0.0), SURF_WEST: (0, -facade_x_m), SURF_EAST: (0, facade_x_m)}
    for surf, (axis, d) in planes.items():
        den = d - pos_t[..., axis]
        den = np.where(np.abs(den) < 1e-9, 1e-9, den)  # a camera on the plane sees it edge-on
        # (I + s n^T / den) R_t^T = R_t^T + s (row `axis` of R_t^T) / den; then R_m on the left.
        rt_t = np.swapaxes(rot_t, -1, -2)
        m = rt_t + shift[..., :, None] * rt_t[..., axis, None, :] / den[..., None, None]
        out[:, :, surf] = np.einsum("lij,ltjk->ltik", rot_mid, m)
    return out


@njit(cache=True)
def _line_coefficients(homs_l, ln, fx, fy, cx, cy, transposed, coef):
    """Per (sample, surface), the mid pose's projection of line ``ln``'s pixel a as three linear functions of a:
    ``coef[j, s] = (x0, x1, y0, y1, z0, z1)`` with image position ((x0 + a x1) / z, (y0 + a y1) / z) and
    z = z0 + a z1 (pixel-index coordinates: pixel i's centre is at i)."""
    for j in range(homs_l.shape[0]):
        for s in range(homs_l.shape[1]):
            h = homs_l[j, s]
            # The pixel's ray (q0, q1, 1): q0 = (x + 0.5 - cx) / fx, q1 = (y + 0.5 - cy) / fy, one of them fixed.
            if transposed:  # render line = image column x, along = image row y
                q0 = (ln + 0.5 - cx) / fx
                base = (h[0, 0] * q0 + h[0, 1] * (0.5 - cy) / fy + h[0, 2],
                        h[1, 0] * q0 + h[1, 1] * (0.5 - cy) / fy + h[1, 2],
                        h[2, 0] * q0 + h[2, 1] * (0.5 - cy) / fy + h[2, 2])
                slope = (h[0, 1] / fy, h[1, 1] / fy, h[2, 1] / fy)
            else:
                q1 = (ln + 0.5 - cy) / fy
                base = (h[0, 0] * (0.5 - cx) / fx + h[0, 1] * q1 + h[0, 2],
                        h[1, 0] * (0.5 - cx) / fx + h[1, 1] * q1 + h[1, 2],
                        h[2, 0] * (0.5 - cx) / fx + h[2, 1] * q1 + h[2, 2])
                slope = (h[0, 0] / fx, h[1, 0] / fx, h[2, 0] / fx)
            coef[j, s, 0] = fx * base[0] + (cx - 0.5) * base[2]
            coef[j, s, 1] = fx * slope[0] + (cx - 0.5) * slope[2]
            coef[j, s, 2] = fy * base[1] + (cy - 0.5) * base[2]
            coef[j, s, 3] = fy * slope[1] + (cy - 0.5) * slope[2]
            coef[j, s, 4] = base[2]
            coef[j, s, 5] = slope[2]


@njit(cache=True)
def _blur_rows(bg, surface, margin, cam, homs, n_path, dt_u_s, lt_s, acc_lin, hits, n_actor, out, l0, l1):
    """Lines ``l0 .. l1 - 1`` of ``path_blur``: each line's reads in C (``rollcam_path_reads``, which gcc
    vectorises; in numba a read cost 17 ns), the coefficients and the sum here."""
    fx, fy, cx, cy = cam[C_FX], cam[C_FY], cam[C_CX], cam[C_CY]
    transposed = cam[C_TRANSPOSED] != 0.0
    n_along = out.shape[1]
    n_s = homs.shape[1]
    u_slot = n_s - 1
    coef = np.empty((n_s, N_SURFACES, 6))
    scratch = np.empty(2 * n_along)
    acc = np.empty((n_along, 3))
    for ln in range(l0, l1):
        _line_coefficients(homs[ln], ln, fx, fy, cx, cy, transposed, coef)
        n = n_path[ln]
        surf = surface[ln + margin, margin:margin + n_along]
        path_reads_c(bg.ctypes.data, bg.shape[0], bg.shape[1], surf.ctypes.data, coef.ctypes.data, n, u_slot,
                     float(ln), lt_s[ln], dt_u_s, 1 if transposed else 0, margin, n_along, scratch.ctypes.data,
                     acc.ctypes.data)
        inv = 1.0 / n
        if hits[ln] > 0:
            inv_a = np.float32(1.0 / n_actor[ln])
            for a in range(n_along):
                for c in range(3):
                    out[ln, a, c] = np.float32(acc[a, c] * inv) + acc_lin[ln, a, c] * inv_a
        else:
            for a in range(n_along):
                for c in range(3):
                    out[ln, a, c] = np.float32(acc[a, c] * inv)


@njit(cache=True, nogil=True)
def path_blur(bg, surface, margin, cam, homs, n_path, dt_u_s, lt_s, acc_lin, hits, n_actor, out):
    """Each render line's background integrated along its pixels' paths, plus its actors' accumulated samples.

    ``out[l, a] = mean_j bg(H[l, j, s] p) + acc_lin[l, a] / n_actor[l]`` (the second term where ``hits[l]``),
    j over line l's ``n_path[l]`` time samples, s the pixel's surface, each read moved by the rolling-shutter
    correction (``lt_s[l]``: seconds per render line; slot ``-1`` of ``homs`` maps from ``dt_u_s`` before
    mid-exposure, for the velocity). ``out`` may be ``acc_lin`` itself: each pixel is read before it is written.
    """
    _blur_rows(bg, surface, margin, cam, homs, n_path, dt_u_s, lt_s, acc_lin, hits, n_actor, out, 0, out.shape[0])


@njit(cache=True, parallel=True, nogil=True)
def path_blur_par(bg, surface, margin, cam, homs, n_path, dt_u_s, lt_s, acc_lin, hits, n_actor, out):
    """``path_blur`` over the numba threads (interleaved blocks of 8 lines)."""
    n = out.shape[0]
    n_blocks = (n + 7) // 8
    for b in prange(n_blocks):
        _blur_rows(bg, surface, margin, cam, homs, n_path, dt_u_s, lt_s, acc_lin, hits, n_actor, out, 8 * b,
                   min(8 * b + 8, n))


def facade_x(world: np.ndarray) -> float:
    """The facade planes' distance from the street's axis (m), from the world table."""
    return float(world[W_FACADE])


def blur_margin(path_px: float, cap: int) -> int:
    """Margin (render px) of the background frame for reads up to ``path_px`` away, at most ``cap``."""
    return int(min(cap, math.ceil(max(path_px, 0.0)) + 2))


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
