"""Numba kernels of the static world: camera poses and background ray casting (street, facades, sky).

Part of the per-line renderer (``rollcam.sim._actors`` holds the actors, ``rollcam.sim._kernels`` the line
painting); table layouts are filled by ``rollcam.sim.compile``. Every function is pure, so every render path
shades identically.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._jitcache import guard

# ---- camera table columns -------------------------------------------------------------------------------
C_FX, C_FY, C_CX, C_CY, C_W, C_H, C_TRANSPOSED = 0, 1, 2, 3, 4, 5, 6
C_POS, C_YAW, C_PITCH, C_ROLL = 7, 10, 11, 12
C_VEL, C_PAN, C_TILT, C_ROLLRATE = 13, 16, 17, 18
C_VIB_ANG, C_VIB_POS, C_VIB_HZ, C_MOVING = 19, 20, 21, 22
CAM_COLS = 24

# ---- lighting table ---------------------------------------------------------------------------------------
L_SUN, L_SUN_RGB, L_AMB, L_HORIZON, L_ZENITH, L_HAZE, L_FOG, L_GLOW = 0, 3, 6, 9, 12, 15, 18, 19
LIGHT_COLS = 20

# ---- world table ------------------------------------------------------------------------------------------
W_KIND, W_ROAD, W_CURB, W_WALK, W_FACADE, W_YHALF = 0, 1, 2, 3, 4, 5
W_ASPHALT, W_SIDEWALK, W_CROSS, W_SEED, W_LEVEL, W_BIN = 6, 9, 12, 13, 14, 15
WORLD_COLS = 16
KIND_STREET, KIND_CHART, KIND_FLAT = 0, 1, 2

# ---- building table ---------------------------------------------------------------------------------------
B_SIDE, B_Y0, B_Y1, B_HEIGHT, B_RGB, B_WIN_RGB, B_FLOOR, B_WIN_W, B_WIN_SP, B_LIT = 0, 1, 2, 3, 4, 7, 10, 11, 12, 13
BLD_COLS = 14

# Background shading tolerates reassociation and fast math functions (NaN/inf semantics kept); every path
# renders the background through the same compiled functions, so results stay identical between paths.
BG_FAST = {"contract", "afn", "reassoc", "arcp", "nsz"}

# ======================================================================================================
# camera
# ======================================================================================================


@njit(cache=True)
def camera_pose(cam, t, rot, pos):
    """World-to-camera rotation (rows: right, down, forward) and camera position at time ``t`` seconds."""
    w = 2.0 * math.pi * cam[C_VIB_HZ] * t
    va, vp = cam[C_VIB_ANG], cam[C_VIB_POS]
    pos[0] = cam[C_POS] + cam[C_VEL] * t + vp * math.sin(w)
    pos[1] = cam[C_POS + 1] + cam[C_VEL + 1] * t + vp * math.sin(1.31 * w + 1.0)
    pos[2] = cam[C_POS + 2] + cam[C_VEL + 2] * t + vp * math.sin(0.77 * w + 2.0)
    yaw = cam[C_YAW] + cam[C_PAN] * t + va * math.sin(1.13 * w + 0.5)
    pitch = cam[C_PITCH] + cam[C_TILT] * t + va * math.sin(0.91 * w + 1.7)
    roll = cam[C_ROLL] + cam[C_ROLLRATE] * t + 0.5 * va * math.sin(1.07 * w + 2.9)
    sy, cy = math.sin(yaw), math.cos(yaw)
    sp, cp = math.sin(pitch), math.cos(pitch)
    sr, cr = math.sin(roll), math.cos(roll)
    fx, fy, fz = sy * cp, cy * cp, sp
    rx, ry, rz = cy, -sy, 0.0
    # up = right x forward
    ux, uy, uz = ry * fz - rz * fy, rz * fx - rx * fz, rx * fy - ry * fx
    r2x, r2y, r2z = cr * rx - sr * ux, cr * ry - sr * uy, cr * rz - sr * uz
    u2x, u2y, u2z = sr * rx + cr * ux, sr * ry + cr * uy, sr * rz + cr * uz
    rot[0, 0], rot[0, 1], rot[0, 2] = r2x, r2y, r2z
    rot[1, 0], rot[1, 1], rot[1, 2] = -u2x, -u2y, -u2z
    rot[2, 0], rot[2, 1], rot[2, 2] = fx, fy, fz


@njit(cache=True)
def pose_table(cam, times, rot_tab, pos_tab):
    """Camera pose at every time (a static camera's pose is computed once and repeated)."""
    moving = cam[C_MOVING] != 0.0
    for k in range(times.shape[0]):
        if k == 0 or moving:
            camera_pose(cam, times[k], rot_tab[k], pos_tab[k])
        else:
            rot_tab[k, :, :] = rot_tab[0]
            pos_tab[k, :] = pos_tab[0]


@njit(cache=True, inline="always")
def to_camera(rot, pos, x, y, z, out):
    """World point to camera frame."""
    dx, dy, dz = x - pos[0], y - pos[1], z - pos[2]
    out[0] = rot[0, 0] * dx + rot[0, 1] * dy + rot[0, 2] * dz
    out[1] = rot[1, 0] * dx + rot[1, 1] * dy + rot[1, 2] * dz
    out[2] = rot[2, 0] * dx + rot[2, 1] * dy + rot[2, 2] * dz


# ======================================================================================================
# background
# ======================================================================================================


@njit(cache=True, fastmath=BG_FAST, inline="always")
def _hash01(ix, iy, seed):
    h = (ix * 374761393 + iy * 668265263 + seed * 2147483647) & 0xFFFFFFFF
    h = ((h ^ (h >> 13)) * 1274126177) & 0xFFFFFFFF
    h = h ^ (h >> 16)
    return (h & 0xFFFFFF) / 16777216.0


@njit(cache=True, fastmath=BG_FAST, inline="always")
def _value_noise(x, y, seed):
    ix, iy = math.floor(x), math.floor(y)
    fx, fy = x - ix, y - iy
    ix, iy = int(ix), int(iy)
    a = _hash01(ix, iy, seed)
    b = _hash01(ix + 1, iy, seed)
    c = _hash01(ix, iy + 1, seed)
    d = _hash01(ix + 1, iy + 1, seed)
    sx, sy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
    return (a + (b - a) * sx) * (1 - sy) + (c + (d - c) * sx) * sy


@njit(cache=True, fastmath=BG_FAST, inline="always")
def building_at(world, lut, side, y):
    """Index of the building on ``side`` (0 west, 1 east) at street coordinate ``y`` (periodic), or -1."""
    yh = world[W_YHALF]
    yy = y + yh
    yy -= math.floor(yy / (2.0 * yh)) * (2.0 * yh)  # periodic street; cheaper than Python's float %
    i = int(yy / world[W_BIN])
    if i < 0 or i >= lut.shape[1]:
        return -1
    return lut[side, i]


@njit(cache=True, fastmath=BG_FAST, inline="always")
def _sun_blocked(world, lut, bld, px, py, pz, light, skip_side):
    """True when a facade stands between point ``p`` and the sun (street canyon shadows)."""
    sx, sy, sz = light[L_SUN], light[L_SUN + 1], light[L_SUN + 2]
    if sz <= 0.0:
        return True
    if sx == 0.0:
        return False
    side = 1 if sx > 0 else 0
    if side == skip_side:
        return False
    xf = world[W_FACADE] if side == 1 else -world[W_FACADE]
    t = (xf - px) / sx
    if t <= 0.0:
        return False
    b = building_at(world, lut, side, py + t * sy)
    if b < 0:
        return False
    return pz + t * sz < bld[b, B_HEIGHT]


@njit(cache=True, fastmath=BG_FAST)
def _ground_albedo(world, gx, gy):
    """Albedo (r, g, b) of the ground at (gx, gy): asphalt with markings, curb, tiled sidewalk."""
    seed = int(world[W_SEED])
    ax = abs(gx)
    road, curb = world[W_ROAD], world[W_ROAD] + world[W_CURB]
    yl = gy
    if ax < road:
        n = _value_noise(gx * 9.0, gy * 9.0, seed) * 0.6 + _value_noise(gx * 1.3, gy * 1.3, seed + 7) * 0.4
        g = 0.75 + 0.5 * n
        r, gg, b = world[W_ASPHALT] * g, world[W_ASPHALT + 1] * g, world[W_ASPHALT + 2] * g
        paint = False
        dc = yl - world[W_CROSS]
        if abs(dc) < 2.0 and ax < road - 0.3:
            paint = (gx + 100.0) % 1.0 < 0.5  # zebra crossing
        elif ax < 0.07:
            paint = (yl % 9.0) < 3.0  # dashed centre line
        elif road - 0.35 < ax < road - 0.2:
            paint = True  # edge line
        if paint:
            return 0.62, 0.62, 0.60
        return r, gg, b
    if ax < curb:
        return 0.45, 0.44, 0.42
    u, v = (ax - curb) / 0.6, yl / 0.6
    iu, iv = math.floor(u), math.floor(v)
    g = 0.85 + 0.3 * _hash01(int(iu), int(iv), seed + 3)
    if u - iu < 0.04 or v - iv < 0.04:
        g *= 0.7  # grout
    g *= 0.9 + 0.2 * _value_noise(gx * 4.0, gy * 4.0, seed + 11)
    return world[W_SIDEWALK] * g, world[W_SIDEWALK + 1] * g, world[W_SIDEWALK + 2] * g


@njit(cache=True, fastmath=BG_FAST)
def _facade(world, bld, b, fy, fz, light):
    """Albedo (r, g, b) and emission (lit windows) of facade ``b`` at street coordinate ``fy``, height ``fz``."""
    y0 = bld[b, B_Y0]
    yh = world[W_YHALF]
    u = fy + yh
    u -= math.floor(u / (2.0 * yh)) * (2.0 * yh)
    u -= yh + y0
    fl = bld[b, B_FLOOR]
    floor_i = math.floor(fz / fl)
    zz = fz - floor_i * fl
    sp = bld[b, B_WIN_SP]
    col_i = math.floor(u / sp)
    uu = u - col_i * sp
    ww = bld[b, B_WIN_W]
    margin = 0.5 * (sp - ww)
    top = bld[b, B_HEIGHT]
    seed = int(world[W_SEED]) + b * 131
    grain = 0.9 + 0.2 * _value_noise(u * 3.0, fz * 3.0, seed)
    r, g, bl = bld[b, B_RGB] * grain, bld[b, B_RGB + 1] * grain, bld[b, B_RGB + 2] * grain
    emit = 0.0
    if fz > top - 0.6:
        r, g, bl = r * 0.75, g * 0.75, bl * 0.75  # cornice
    elif floor_i == 0:
        if 0.1 < zz < 2.7 and 0.25 < uu < sp - 0.25:
            shop = _hash01(int(col_i), 17, seed)
            r, g, bl = bld[b, B_WIN_RGB] * 0.8, bld[b, B_WIN_RGB + 1] * 0.8, bld[b, B_WIN_RGB + 2] * 0.8
            if shop < 0.35:
                r, g, bl = 0.12 + 0.2 * shop, 0.08, 0.06  # door
    elif 0.9 < zz < 2.5 and margin < uu < sp - margin:
        h = _hash01(int(col_i), int(floor_i), seed)
        r = bld[b, B_WIN_RGB] * (0.7 + 0.6 * h)
        g = bld[b, B_WIN_RGB + 1] * (0.7 + 0.6 * h)
        bl = bld[b, B_WIN_RGB + 2] * (0.7 + 0.6 * h)
        if h < bld[b, B_LIT]:
            emit = light[L_GLOW]
        if zz < 1.0 or zz > 2.4 or uu < margin + 0.06 or uu > sp - margin - 0.06:
            r, g, bl = r * 0.5 + 0.1, g * 0.5 + 0.1, bl * 0.5 + 0.1  # frame
    return r, g, bl, emit


@njit(cache=True, fastmath=BG_FAST, inline="always")
def _sky(light, dx, dy, dz):
    n = math.sqrt(dx * dx + dy * dy + dz * dz)
    s = math.sqrt(max(dz / n, 0.0))
    cosg = (dx * light[L_SUN] + dy * light[L_SUN + 1] + dz * light[L_SUN + 2]) / n
    glow = cosg**32 * 0.6 if cosg > 0.0 else 0.0
    return (light[L_HORIZON] * (1.0 - s) + light[L_ZENITH] * s + light[L_SUN_RGB] * glow,
            light[L_HORIZON + 1] * (1.0 - s) + light[L_ZENITH + 1] * s + light[L_SUN_RGB + 1] * glow,
            light[L_HORIZON + 2] * (1.0 - s) + light[L_ZENITH + 2] * s + light[L_SUN_RGB + 2] * glow)


@njit(cache=True, fastmath=BG_FAST, inline="always")
def background_pixel(world, lut, bld, light, cam, rot, pos, xi, yi):
    """Linear RGB radiance (r, g, b) of the static world seen through image pixel (xi, yi) from (rot, pos)."""
    kind = int(world[W_KIND])
    if kind == KIND_FLAT:
        return world[W_LEVEL], world[W_LEVEL], world[W_LEVEL]
    if kind == KIND_CHART:
        # A uniform matte board filling the view: edges measured against it need no flat-field correction.
        return world[W_ASPHALT], world[W_ASPHALT + 1], world[W_ASPHALT + 2]
    cx = (xi + 0.5 - cam[C_CX]) / cam[C_FX]
    cy = (yi + 0.5 - cam[C_CY]) / cam[C_FY]
    dx = cx * rot[0, 0] + cy * rot[1, 0] + rot[2, 0]
    dy = cx * rot[0, 1] + cy * rot[1, 1] + rot[2, 1]
    dz = cx * rot[0, 2] + cy * rot[1, 2] + rot[2, 2]
    xf = world[W_FACADE]
    t_hit = 1e30
    surf = 0  # 0 sky, 1 ground, 2 facade
    side = 0
    if dz < 0.0 and pos[2] > 0.0:
        t = -pos[2] / dz
        gx = pos[0] + t * dx
        if abs(gx) < xf:
            t_hit, surf = t, 1
    if dx != 0.0:
        side = 1 if dx > 0 else 0
        t = ((xf if side == 1 else -xf) - pos[0]) / dx
        if 0.0 < t < t_hit:
            fy, fz = pos[1] + t * dy, pos[2] + t * dz
            if fz >= 0.0:
                b = building_at(world, lut, side, fy)
                if b >= 0 and fz < bld[b, B_HEIGHT]:
                    t_hit, surf = t, 2
    emit = 0.0
    if surf == 0:
        return _sky(light, dx, dy, dz)
    hx, hy, hz = pos[0] + t_hit * dx, pos[1] + t_hit * dy, pos[2] + t_hit * dz
    if surf == 1:
        ar, ag, ab = _ground_albedo(world, hx, hy)
        ndotl = light[L_SUN + 2]
        lit = 0.0 if _sun_blocked(world, lut, bld, hx, hy, 0.0, light, -1) else 1.0
    else:
        b = building_at(world, lut, side, hy)
        ar, ag, ab, emit = _facade(world, bld, b, hy, hz, light)
        ndotl = -light[L_SUN] if side == 1 else light[L_SUN]
        lit = 0.0
        if ndotl > 0.0 and not _sun_blocked(world, lut, bld, hx, hy, hz, light, side):
            lit = 1.0
    ndotl = max(ndotl, 0.0) * lit
    dist = t_hit * math.sqrt(dx * dx + dy * dy + dz * dz)
    f = math.exp(-dist / light[L_FOG])
    g = 1.0 - f
    return ((ar * (light[L_AMB] + light[L_SUN_RGB] * ndotl + emit)) * f + light[L_HAZE] * g,
            (ag * (light[L_AMB + 1] + light[L_SUN_RGB + 1] * ndotl + emit)) * f + light[L_HAZE + 1] * g,
            (ab * (light[L_AMB + 2] + light[L_SUN_RGB + 2] * ndotl + emit)) * f + light[L_HAZE + 2] * g)


@njit(cache=True, fastmath=BG_FAST)
def background_line(world, lut, bld, light, cam, rot, pos, line, out_line):
    """Render one render-space line of the background from pose (rot, pos) into ``out_line`` (n x 3)."""
    transposed = cam[C_TRANSPOSED] != 0.0
    for a in range(out_line.shape[0]):
        if transposed:
            r, g, b = background_pixel(world, lut, bld, light, cam, rot, pos, line, a)
        else:
            r, g, b = background_pixel(world, lut, bld, light, cam, rot, pos, a, line)
        out_line[a, 0], out_line[a, 1], out_line[a, 2] = r, g, b


@njit(cache=True, parallel=True)
def background_image(world, lut_b, bld, light, cam, t, out):
    """Whole background at one time (the static layer cache)."""
    rot = np.empty((3, 3))
    pos = np.empty(3)
    camera_pose(cam, t, rot, pos)
    for line in prange(out.shape[0]):
        background_line(world, lut_b, bld, light, cam, rot, pos, line, out[line])


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
