"""Numba kernels of the static world: camera poses, and the background (street, facades, sky) and sun shadows
through the C shader.

Part of the per-line renderer (``actors`` holds the actors, ``lines`` the line
painting, ``shader`` loads the C shader, ``sim/render/rollcam_shade.c``, that casts each pixel's ray and
shades what it hits); table layouts are filled by ``tables``. Every function is pure, so every
render path shades identically.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .._jitcache import guard
from .shader import background_line_c, background_span_c, check_layout, library, sun_blocked_c

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
B_MAT = 14
BLD_COLS = 15
MAT_PLASTER, MAT_BRICK, MAT_STONE, MAT_GLASS = 0, 1, 2, 3
"""A facade's material (``B_MAT``), in ``rollcam.sim.scene.FACADES`` order."""
NO_BUILDING_HEIGHT = -1e300
"""Height of the building table's last row, the sentinel that the lookup's empty bins name (see ``compile``)."""

SHADE_LAYOUT = (C_FX, C_FY, C_CX, C_CY, C_TRANSPOSED, L_SUN, L_SUN_RGB, L_AMB, L_HORIZON, L_ZENITH, L_HAZE, L_FOG,
                L_GLOW, W_KIND, W_ROAD, W_CURB, W_FACADE, W_YHALF, W_ASPHALT, W_SIDEWALK, W_CROSS, W_SEED, W_LEVEL,
                W_BIN, KIND_STREET, KIND_FLAT, B_Y0, B_HEIGHT, B_RGB, B_WIN_RGB, B_FLOOR, B_WIN_W, B_WIN_SP, B_LIT,
                B_MAT, BLD_COLS, MAT_PLASTER, MAT_BRICK, MAT_STONE, MAT_GLASS)
"""The columns the C shader reads, in the order ``rollcam_shade_layout`` reports them."""
check_layout(library(), SHADE_LAYOUT)


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
# background (the C shader)
# ======================================================================================================


@njit(cache=True, inline="always")
def sun_blocked(world, lut, bld, px, py, pz, light, skip_side):
    """True when a facade stands between point ``p`` and the sun (street canyon shadows); ``skip_side``: the
    facade (0 west, 1 east) the point is on, or -1."""
    return sun_blocked_c(world.ctypes.data, lut.ctypes.data, lut.shape[1] - 1, bld.ctypes.data, light.ctypes.data,
                         px, py, pz, skip_side) != 0


@njit(cache=True, inline="always")
def background_line(world, lut, bld, light, cam, rot, pos, line, out_line):
    """Render one render-space line of the background from pose (rot, pos) into ``out_line`` (n x 3 float32).

    Every array must be C-contiguous (the kernels' tables and buffers are): the shader reads them by address.
    """
    background_line_c(world.ctypes.data, lut.ctypes.data, lut.shape[1] - 1, bld.ctypes.data, light.ctypes.data,
                      cam.ctypes.data, rot.ctypes.data, pos.ctypes.data, line, out_line.ctypes.data,
                      out_line.shape[0])


@njit(cache=True, inline="always")
def background_span(world, lut, bld, light, cam, rot, pos, line, a_begin, a_end, out, surface):
    """Pixels ``a_begin .. a_end - 1`` of render-space line ``line`` (a float: indices beyond the image are the
    blur's margins) from pose (rot, pos) into ``out`` (float32, (a_end - a_begin) x 3) and each pixel's surface
    code into ``surface`` (int8, same length; an empty array skips it). Same values as ``background_line``."""
    background_span_c(world.ctypes.data, lut.ctypes.data, lut.shape[1] - 1, bld.ctypes.data, light.ctypes.data,
                      cam.ctypes.data, rot.ctypes.data, pos.ctypes.data, line, a_begin, a_end, out.ctypes.data,
                      surface.ctypes.data if surface.shape[0] > 0 else 0)


@njit(cache=True, parallel=True, nogil=True)
def background_image(world, lut_b, bld, light, cam, t, out):
    """Whole background at one time (the static layer cache)."""
    rot = np.empty((3, 3))
    pos = np.empty(3)
    camera_pose(cam, t, rot, pos)
    for line in prange(out.shape[0]):
        background_line(world, lut_b, bld, light, cam, rot, pos, line, out[line])


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
