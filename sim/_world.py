"""Numba kernels of the static world: camera poses and background ray casting (street, facades, sky).

Part of the per-line renderer (``rollcam.sim._actors`` holds the actors, ``rollcam.sim._kernels`` the line
painting, ``rollcam.sim._shade`` the materials a ray hits); table layouts are filled by ``rollcam.sim.compile``.
Every function is pure, so every render path shades identically.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._jitcache import guard
from ._shade import (
    BG_FAST,
    CURB_RGB,
    NO_CELL,
    asphalt_albedo,
    facade_albedo,
    fog_transmittance,
    sidewalk_albedo,
    sky,
    value_noise,
)

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


@njit(cache=True, nogil=True)
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


@njit(cache=True, fastmath=BG_FAST, error_model="numpy", inline="always")
def street_bin(y, y_half, bin_m):
    """Bin of the building lookup holding street coordinate ``y`` (the street repeats every 2 * y_half)."""
    yy = y + y_half
    yy -= math.floor(yy / (2.0 * y_half)) * (2.0 * y_half)  # periodic street; cheaper than Python's float %
    return int(yy / bin_m)


@njit(cache=True, fastmath=BG_FAST, inline="always")
def building_at(world, lut, side, y):
    """Index of the building on ``side`` (0 west, 1 east) at street coordinate ``y`` (periodic), or -1."""
    i = street_bin(y, world[W_YHALF], world[W_BIN])
    if i < 0 or i >= lut.shape[1]:
        return -1
    return lut[side, i]


@njit(cache=True, fastmath=BG_FAST, error_model="numpy", inline="always")
def sun_probe(px, py, pz, sun_x, sun_y, sun_z, facade_x, skip_side):
    """Where the ray from point p towards the sun crosses a facade plane (street canyon shadows).

    Returns (state, side, y, z): state 0 unshadowed, 1 shadowed (sun below the horizon), 2 shadowed exactly
    when a building stands on ``side`` at street coordinate y and is taller than z.
    """
    if sun_z <= 0.0:
        return 1, 0, 0.0, 0.0
    if sun_x == 0.0:
        return 0, 0, 0.0, 0.0
    side = 1 if sun_x > 0 else 0
    if side == skip_side:
        return 0, 0, 0.0, 0.0
    t = ((facade_x if side == 1 else -facade_x) - px) / sun_x
    if t <= 0.0:
        return 0, 0, 0.0, 0.0
    return 2, side, py + t * sun_y, pz + t * sun_z


@njit(cache=True, fastmath=BG_FAST, inline="always")
def _sun_blocked(world, lut, bld, px, py, pz, light, skip_side):
    """True when a facade stands between point ``p`` and the sun (street canyon shadows)."""
    state, side, y, z = sun_probe(px, py, pz, light[L_SUN], light[L_SUN + 1], light[L_SUN + 2], world[W_FACADE],
                                  skip_side)
    if state != 2:
        return state == 1
    b = building_at(world, lut, side, y)
    return b >= 0 and z < bld[b, B_HEIGHT]


@njit(cache=True, fastmath=BG_FAST, error_model="numpy")
def background_line(world, lut, bld, light, cam, rot, pos, line, out_line):
    """Render one render-space line of the background from pose (rot, pos) into ``out_line`` (n x 3).

    One function with no array-taking callee: arrays handed to a callee (even an inlined one) are
    reference-counted per call, which in this loop cost more than the shading (see ``rollcam.sim._shade``).
    Every table value the loop needs is read into a local first.
    """
    n = out_line.shape[0]
    kind = int(world[W_KIND])
    if kind != KIND_STREET:
        # A flat level, or a chart's uniform matte board filling the view (no flat-field correction needed).
        v0 = world[W_LEVEL] if kind == KIND_FLAT else world[W_ASPHALT]
        v1 = world[W_LEVEL] if kind == KIND_FLAT else world[W_ASPHALT + 1]
        v2 = world[W_LEVEL] if kind == KIND_FLAT else world[W_ASPHALT + 2]
        for a in range(n):
            out_line[a, 0], out_line[a, 1], out_line[a, 2] = v0, v1, v2
        return
    transposed = cam[C_TRANSPOSED] != 0.0
    fx, fy_px, cx0, cy0 = cam[C_FX], cam[C_FY], cam[C_CX], cam[C_CY]
    px, py, pz = pos[0], pos[1], pos[2]
    xf, y_half, bin_m, n_bins = world[W_FACADE], world[W_YHALF], world[W_BIN], lut.shape[1]
    seed = int(world[W_SEED])
    road, curb, cross_y = world[W_ROAD], world[W_ROAD] + world[W_CURB], world[W_CROSS]
    as_r, as_g, as_b = world[W_ASPHALT], world[W_ASPHALT + 1], world[W_ASPHALT + 2]
    sw_r, sw_g, sw_b = world[W_SIDEWALK], world[W_SIDEWALK + 1], world[W_SIDEWALK + 2]
    sun_x, sun_y, sun_z = light[L_SUN], light[L_SUN + 1], light[L_SUN + 2]
    sun_r, sun_g, sun_b = light[L_SUN_RGB], light[L_SUN_RGB + 1], light[L_SUN_RGB + 2]
    amb_r, amb_g, amb_b = light[L_AMB], light[L_AMB + 1], light[L_AMB + 2]
    hz_r, hz_g, hz_b = light[L_HORIZON], light[L_HORIZON + 1], light[L_HORIZON + 2]
    ze_r, ze_g, ze_b = light[L_ZENITH], light[L_ZENITH + 1], light[L_ZENITH + 2]
    ha_r, ha_g, ha_b = light[L_HAZE], light[L_HAZE + 1], light[L_HAZE + 2]
    inv_fog, glow = 1.0 / light[L_FOG], light[L_GLOW]
    # Lattice cells of the four value noises (fine and coarse asphalt, sidewalk, facade), reused by neighbours.
    c_fine, c_coarse, c_walk, c_wall = NO_CELL, NO_CELL, NO_CELL, NO_CELL
    for a in range(n):
        xi, yi = (line, a) if transposed else (a, line)
        cx = (xi + 0.5 - cx0) / fx
        cy = (yi + 0.5 - cy0) / fy_px
        dx = cx * rot[0, 0] + cy * rot[1, 0] + rot[2, 0]
        dy = cx * rot[0, 1] + cy * rot[1, 1] + rot[2, 1]
        dz = cx * rot[0, 2] + cy * rot[1, 2] + rot[2, 2]
        t_hit = 1e30
        surf = 0  # 0 sky, 1 ground, 2 facade
        side = 0
        b_hit = 0
        if dz < 0.0 and pz > 0.0:
            t = -pz / dz
            if abs(px + t * dx) < xf:
                t_hit, surf = t, 1
        if dx != 0.0:
            side = 1 if dx > 0 else 0
            t = ((xf if side == 1 else -xf) - px) / dx
            if 0.0 < t < t_hit:
                fz = pz + t * dz
                if fz >= 0.0:
                    i = street_bin(py + t * dy, y_half, bin_m)
                    b = lut[side, i] if 0 <= i < n_bins else -1
                    if b >= 0 and fz < bld[b, B_HEIGHT]:
                        t_hit, surf, b_hit = t, 2, b
        if surf == 0:
            r, g, bl = sky(dx, dy, dz, sun_x, sun_y, sun_z, hz_r, hz_g, hz_b, ze_r, ze_g, ze_b, sun_r, sun_g, sun_b)
            out_line[a, 0], out_line[a, 1], out_line[a, 2] = r, g, bl
            continue
        hx, hy, hz = px + t_hit * dx, py + t_hit * dy, pz + t_hit * dz
        emit = 0.0
        if surf == 1:
            ax = abs(hx)
            if ax < road:
                n_fine, c_fine = value_noise(hx * 9.0, hy * 9.0, seed, c_fine)
                n_coarse, c_coarse = value_noise(hx * 1.3, hy * 1.3, seed + 7, c_coarse)
                ar, ag, ab = asphalt_albedo(hx, hy, n_fine * 0.6 + n_coarse * 0.4, road, cross_y, as_r, as_g, as_b)
            elif ax < curb:
                ar, ag, ab = CURB_RGB
            else:
                n_walk, c_walk = value_noise(hx * 4.0, hy * 4.0, seed + 11, c_walk)
                ar, ag, ab = sidewalk_albedo(hx, hy, n_walk, seed, curb, sw_r, sw_g, sw_b)
            ndotl = sun_z
            skip = -1
        else:
            u = hy + y_half
            u -= math.floor(u / (2.0 * y_half)) * (2.0 * y_half)
            u -= y_half + bld[b_hit, B_Y0]
            n_wall, c_wall = value_noise(u * 3.0, hz * 3.0, seed + b_hit * 131, c_wall)
            ar, ag, ab, emit = facade_albedo(
                u, hz, n_wall, seed + b_hit * 131, bld[b_hit, B_FLOOR], bld[b_hit, B_WIN_SP], bld[b_hit, B_WIN_W],
                bld[b_hit, B_HEIGHT], bld[b_hit, B_RGB], bld[b_hit, B_RGB + 1], bld[b_hit, B_RGB + 2],
                bld[b_hit, B_WIN_RGB], bld[b_hit, B_WIN_RGB + 1], bld[b_hit, B_WIN_RGB + 2], bld[b_hit, B_LIT], glow)
            ndotl = -sun_x if side == 1 else sun_x
            skip = side
        lit = 0.0
        if ndotl > 0.0:
            state, s_side, s_y, s_z = sun_probe(hx, hy, hz, sun_x, sun_y, sun_z, xf, skip)
            lit = 1.0
            if state == 1:
                lit = 0.0
            elif state == 2:
                i = street_bin(s_y, y_half, bin_m)
                b = lut[s_side, i] if 0 <= i < n_bins else -1
                if b >= 0 and s_z < bld[b, B_HEIGHT]:
                    lit = 0.0
        ndotl = max(ndotl, 0.0) * lit
        dist = t_hit * math.sqrt(dx * dx + dy * dy + dz * dz)
        f = fog_transmittance(dist * inv_fog)
        g = 1.0 - f
        out_line[a, 0] = (ar * (amb_r + sun_r * ndotl + emit)) * f + ha_r * g
        out_line[a, 1] = (ag * (amb_g + sun_g * ndotl + emit)) * f + ha_g * g
        out_line[a, 2] = (ab * (amb_b + sun_b * ndotl + emit)) * f + ha_b * g


@njit(cache=True, parallel=True, nogil=True)
def background_image(world, lut_b, bld, light, cam, t, out):
    """Whole background at one time (the static layer cache)."""
    rot = np.empty((3, 3))
    pos = np.empty(3)
    camera_pose(cam, t, rot, pos)
    for line in prange(out.shape[0]):
        background_line(world, lut_b, bld, light, cam, rot, pos, line, out[line])


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
