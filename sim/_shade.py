"""Numba kernels of the street's materials: procedural ground, facade and sky shading, scalars in, scalars out.

Part of the per-line renderer: ``rollcam.sim._world`` casts each pixel's ray and calls these for the colour of
what it hit. They take plain numbers, never arrays, on purpose: numba reference-counts every array a called or
inlined function receives, and in the per-pixel loop those atomic counts (a dozen per pixel, on counters both
render threads share) cost more than the shading itself. Every render path shades through these same
functions, so they stay bit-identical between paths.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._jitcache import guard

# Background shading tolerates reassociation and fast math functions (NaN/inf semantics kept); every path
# renders the background through the same compiled functions, so results stay identical between paths.
BG_FAST = {"contract", "afn", "reassoc", "arcp", "nsz"}


@njit(cache=True, fastmath=BG_FAST, error_model="numpy", inline="always")
def hash01(ix, iy, seed):
    """Integer lattice hash to [0, 1)."""
    h = (ix * 374761393 + iy * 668265263 + seed * 2147483647) & 0xFFFFFFFF
    h = ((h ^ (h >> 13)) * 1274126177) & 0xFFFFFFFF
    h = h ^ (h >> 16)
    return (h & 0xFFFFFF) / 16777216.0


NO_CELL = (-(1 << 62), 0, 0, 0.0, 0.0, 0.0, 0.0)
"""A noise cell state that matches no lattice cell (see ``value_noise``)."""


@njit(cache=True, fastmath=BG_FAST, error_model="numpy", inline="always")
def value_noise(x, y, seed, cell):
    """Smooth value noise in [0, 1) on the unit lattice, and the lattice cell it used.

    ``cell`` is the state a previous call returned (or ``NO_CELL``): neighbouring pixels mostly fall in the
    same cell, whose four corner hashes are then reused instead of recomputed. The value is the same either
    way (the hashes are pure integer functions), so the reuse is exact.
    """
    fx0, fy0 = math.floor(x), math.floor(y)
    fx, fy = x - fx0, y - fy0
    ix, iy = int(fx0), int(fy0)
    if ix != cell[0] or iy != cell[1] or seed != cell[2]:
        cell = (ix, iy, seed, hash01(ix, iy, seed), hash01(ix + 1, iy, seed), hash01(ix, iy + 1, seed),
                hash01(ix + 1, iy + 1, seed))
    a, b, c, d = cell[3], cell[4], cell[5], cell[6]
    sx, sy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
    return (a + (b - a) * sx) * (1 - sy) + (c + (d - c) * sx) * sy, cell


@njit(cache=True, fastmath=BG_FAST, error_model="numpy", inline="always")
def asphalt_albedo(gx, gy, noise, road, cross_y, asph_r, asph_g, asph_b):
    """Albedo (r, g, b) of the road at (gx, gy) (``|gx| < road``, its half width): asphalt with markings.

    ``noise`` is the asphalt's grain, 0.6 x fine + 0.4 x coarse value noise (see ``ground_noise``).
    """
    ax = abs(gx)
    paint = False
    if abs(gy - cross_y) < 2.0 and ax < road - 0.3:
        paint = (gx + 100.0) % 1.0 < 0.5  # zebra crossing
    elif ax < 0.07:
        paint = (gy % 9.0) < 3.0  # dashed centre line
    elif road - 0.35 < ax < road - 0.2:
        paint = True  # edge line
    if paint:
        return 0.62, 0.62, 0.60
    g = 0.75 + 0.5 * noise
    return asph_r * g, asph_g * g, asph_b * g


@njit(cache=True, fastmath=BG_FAST, error_model="numpy", inline="always")
def sidewalk_albedo(gx, gy, noise, seed, curb, walk_r, walk_g, walk_b):
    """Albedo (r, g, b) of the tiled sidewalk at (gx, gy) (beyond the curb's outer edge ``curb``)."""
    u, v = (abs(gx) - curb) / 0.6, gy / 0.6
    iu, iv = math.floor(u), math.floor(v)
    g = 0.85 + 0.3 * hash01(int(iu), int(iv), seed + 3)
    if u - iu < 0.04 or v - iv < 0.04:
        g *= 0.7  # grout
    g *= 0.9 + 0.2 * noise
    return walk_r * g, walk_g * g, walk_b * g


CURB_RGB = (0.45, 0.44, 0.42)


@njit(cache=True, fastmath=BG_FAST, error_model="numpy", inline="always")
def facade_albedo(u, fz, noise, seed, floor_h, win_sp, win_w, top, wall_r, wall_g, wall_b, win_r, win_g, win_b,
                  lit_frac, glow):
    """Albedo (r, g, b) and emission (lit windows) of a facade at ``u`` metres along it, height ``fz``.

    ``noise`` is the wall's grain, value noise at (3 u, 3 fz) with the building's seed.
    """
    floor_i = math.floor(fz / floor_h)
    zz = fz - floor_i * floor_h
    col_i = math.floor(u / win_sp)
    uu = u - col_i * win_sp
    margin = 0.5 * (win_sp - win_w)
    grain = 0.9 + 0.2 * noise
    r, g, bl = wall_r * grain, wall_g * grain, wall_b * grain
    emit = 0.0
    if fz > top - 0.6:
        r, g, bl = r * 0.75, g * 0.75, bl * 0.75  # cornice
    elif floor_i == 0:
        if 0.1 < zz < 2.7 and 0.25 < uu < win_sp - 0.25:
            shop = hash01(int(col_i), 17, seed)
            r, g, bl = win_r * 0.8, win_g * 0.8, win_b * 0.8
            if shop < 0.35:
                r, g, bl = 0.12 + 0.2 * shop, 0.08, 0.06  # door
    elif 0.9 < zz < 2.5 and margin < uu < win_sp - margin:
        h = hash01(int(col_i), int(floor_i), seed)
        r, g, bl = win_r * (0.7 + 0.6 * h), win_g * (0.7 + 0.6 * h), win_b * (0.7 + 0.6 * h)
        if h < lit_frac:
            emit = glow
        if zz < 1.0 or zz > 2.4 or uu < margin + 0.06 or uu > win_sp - margin - 0.06:
            r, g, bl = r * 0.5 + 0.1, g * 0.5 + 0.1, bl * 0.5 + 0.1  # frame
    return r, g, bl, emit


@njit(cache=True, fastmath=BG_FAST, error_model="numpy", inline="always")
def sky(dx, dy, dz, sun_x, sun_y, sun_z, hor_r, hor_g, hor_b, zen_r, zen_g, zen_b, sun_r, sun_g, sun_b):
    """Radiance (r, g, b) of the sky in direction (dx, dy, dz): horizon-to-zenith gradient and a sun glow."""
    n = math.sqrt(dx * dx + dy * dy + dz * dz)
    s = math.sqrt(max(dz / n, 0.0))
    cosg = (dx * sun_x + dy * sun_y + dz * sun_z) / n
    glow = cosg**32 * 0.6 if cosg > 0.0 else 0.0
    return (hor_r * (1.0 - s) + zen_r * s + sun_r * glow, hor_g * (1.0 - s) + zen_g * s + sun_g * glow,
            hor_b * (1.0 - s) + zen_b * s + sun_b * glow)


FOG_STEPS = 16
"""Table steps per fog distance of ``fog_transmittance``: exp(-x) = table[k] * exp(-(x - k / FOG_STEPS))."""
_FOG_TABLE = np.exp(-np.arange(64 * FOG_STEPS + 1) / FOG_STEPS)


@njit(cache=True, fastmath=BG_FAST, error_model="numpy", inline="always")
def fog_transmittance(x):
    """exp(-x) for x >= 0 (distance over fog distance), to a relative 1e-10, without a libm call per pixel.

    A table holds exp(-k / FOG_STEPS); the rest, r < 1 / FOG_STEPS, is a degree-5 Taylor series (its first
    omitted term is below r^6 / 720 < 1e-10). Beyond x = 64 (transmittance 2e-28) it is 0.
    """
    k = int(x * FOG_STEPS)
    if k >= _FOG_TABLE.shape[0] - 1:
        return 0.0
    r = x - k * (1.0 / FOG_STEPS)
    return _FOG_TABLE[k] * (1.0 - r * (1.0 - r * (0.5 - r * (1.0 / 6.0 - r * (1.0 / 24.0 - r * (1.0 / 120.0))))))


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
