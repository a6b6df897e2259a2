"""Articulated walker model (numba): where a pedestrian is and how its body parts are posed at time t.

Also defines the actor table layout shared by the render kernels (``actors``). Proportions
follow standard anthropometric ratios of body height; the gait is a sinusoidal hip/knee/shoulder/elbow
model whose phase follows distance walked (so stride frequency follows speed).
"""

from __future__ import annotations

import math

from numba import njit

from .._jitcache import guard

# ---- actor table ------------------------------------------------------------------------------------------
A_TYPE, A_STATIC, A_SPEED, A_ID = 0, 1, 2, 3
# pedestrian
P_LANE_X, P_YC, P_HALF, P_OFF, P_SPEED, P_H, P_BUILD, P_PHASE, P_DIR = 4, 5, 6, 7, 8, 9, 10, 11, 12
P_LONG_HAIR, P_SLEEVES, P_STRIDE, P_SKIN, P_HAIR, P_SHIRT, P_PANTS, P_SHOES = 13, 14, 15, 16, 19, 22, 25, 28
P_SHADOW = 31  # contact shadow strength at its centre (0: none)
P_CAST_X, P_CAST_Y, P_CAST_S = 32, 33, 34  # sun's cast shadow: ground offset per metre of height; strength RGB
P_BAG_KIND, P_BAG, P_SKIRT = 37, 38, 41  # what the walker carries (BAG_*), its colour RGB; 1 for a skirt
# chart bar
R_X0, R_WIDTH, R_VX, R_PERIOD, R_RGB = 4, 5, 6, 7, 8
ACTOR_COLS = 42
TYPE_PEDESTRIAN, TYPE_BAR = 0, 1
TYPE_PROP = 2  # street props: their columns in rollcam.sim.render.props
BAG_NONE, BAG_BACKPACK, BAG_SHOULDER = 0, 1, 2
COL_SKIN, COL_HAIR, COL_SHIRT, COL_PANTS, COL_SHOES, COL_BAG = 0, 1, 2, 3, 4, 5
"""A part's material (``col_idx``): its colour column (``P_SKIN + 3 * c`` for the first five, ``P_BAG``) and its
surface texture (``actors.TEX_CONTRAST``)."""



@njit(cache=True)
def pedestrian_root(act, t, out):
    """Root position (x, y), heading sign along Y and distance walked, at time ``t``; fills ``out[0:4]``."""
    half = act[P_HALF]
    d = act[P_OFF] + act[P_SPEED] * t
    m = d % (4.0 * half)
    if m < 2.0 * half:
        y, sgn = -half + m, 1.0
    else:
        y, sgn = half - (m - 2.0 * half), -1.0
    sgn *= act[P_DIR]
    out[0] = act[P_LANE_X]
    out[1] = act[P_YC] + y * act[P_DIR]
    out[2] = sgn
    out[3] = d


@njit(cache=True, inline="always")
def _limb(px, py, pz, fwd_x, fwd_y, ang, length, out, i):
    s, c = math.sin(ang), math.cos(ang)
    out[i, 0] = px + length * s * fwd_x
    out[i, 1] = py + length * s * fwd_y
    out[i, 2] = pz - length * c


@njit(cache=True)
def pedestrian_skeleton(act, t, seg, rad, col_idx, root, joints):
    """World-space capsules of a walker at time ``t``: seg[p] = (ax, ay, az, bx, by, bz), rad[p] metres.

    Part 0 is the head (its face is drawn on it: ``lines``). ``col_idx[p]`` selects the material
    (``COL_*``); ``root`` (4) receives the root state (see ``pedestrian_root``) and ``joints`` (5 x 3) is
    scratch. Returns the part count: 18 capsules, and a 19th for a bag. A skirt replaces the pelvis (the shins
    below it are bare).
    """
    pedestrian_root(act, t, root)
    x0, y0, sgn, dist = root[0], root[1], root[2], root[3]
    h, bd = act[P_H], act[P_BUILD]
    phi = 2.0 * math.pi * dist / act[P_STRIDE] + act[P_PHASE]
    fx, fy = 0.0, sgn  # heading along +/-Y
    lx, ly = sgn, 0.0  # lateral (to the walker's right when heading +Y)
    sw = min(1.0, act[P_SPEED] / 1.0)  # amplitude of swing grows with speed up to normal walking
    bob = 0.012 * h * math.cos(2.0 * phi) * sw
    hip_z = 0.530 * h + bob
    sh_z = 0.815 * h + bob
    n = 0
    # head (slightly elongated), hair, neck
    hz = 0.925 * h + bob
    seg[n, 0], seg[n, 1], seg[n, 2] = x0, y0, hz - 0.018 * h
    seg[n, 3], seg[n, 4], seg[n, 5] = x0, y0, hz + 0.012 * h
    rad[n], col_idx[n] = 0.058 * h, COL_SKIN
    n += 1
    back = -0.012 * h
    seg[n, 0], seg[n, 1], seg[n, 2] = x0 + back * fx, y0 + back * fy, hz + 0.004 * h
    bz = hz - (0.075 * h if act[P_LONG_HAIR] > 0 else 0.006 * h)
    seg[n, 3], seg[n, 4], seg[n, 5] = x0 + 1.6 * back * fx, y0 + 1.6 * back * fy, bz
    rad[n], col_idx[n] = 0.060 * h, COL_HAIR
    n += 1
    seg[n, 0], seg[n, 1], seg[n, 2] = x0, y0, 0.835 * h + bob
    seg[n, 3], seg[n, 4], seg[n, 5] = x0, y0, 0.875 * h + bob
    rad[n], col_idx[n] = 0.028 * h, COL_SKIN
    n += 1
    # Trunk: a round abdomen, a chest running across it (wider than deep: ~0.26 h across the shoulders,
    # ~0.13 h deep, so the waist narrows under it seen from the front) and a pelvis, also across.
    seg[n, 0], seg[n, 1], seg[n, 2] = x0, y0, hip_z + 0.07 * h
    seg[n, 3], seg[n, 4], seg[n, 5] = x0, y0, sh_z - 0.055 * h
    rad[n], col_idx[n] = 0.08 * h * bd, COL_SHIRT
    n += 1
    chw = 0.065 * h * bd
    seg[n, 0], seg[n, 1], seg[n, 2] = x0 - chw * lx, y0 - chw * ly, sh_z - 0.045 * h
    seg[n, 3], seg[n, 4], seg[n, 5] = x0 + chw * lx, y0 + chw * ly, sh_z - 0.045 * h
    rad[n], col_idx[n] = 0.065 * h * bd, COL_SHIRT
    n += 1
    skirt = act[P_SKIRT] > 0.0
    if skirt:  # from the hips to the knees, around both thighs (which take its colour); bare shins below
        seg[n, 0], seg[n, 1], seg[n, 2] = x0, y0, hip_z
        seg[n, 3], seg[n, 4], seg[n, 5] = x0, y0, hip_z - 0.12 * h
        rad[n], col_idx[n] = 0.095 * h * bd, COL_PANTS
    else:
        hpw = 0.045 * h * bd
        seg[n, 0], seg[n, 1], seg[n, 2] = x0 - hpw * lx, y0 - hpw * ly, hip_z + 0.02 * h
        seg[n, 3], seg[n, 4], seg[n, 5] = x0 + hpw * lx, y0 + hpw * ly, hip_z + 0.02 * h
        rad[n], col_idx[n] = 0.058 * h * bd, COL_PANTS
    n += 1
    shin_col = COL_SKIN if skirt else COL_PANTS
    # Hip joints sit ~0.1 h apart; shoulder joints ~0.28 h apart, so arms hang just clear of the waist.
    leg_x = 0.05 * h * bd
    arm_x = 0.105 * h * bd + 0.035 * h
    # legs and arms, left (s=-1) and right (s=+1); the right leg leads at phi = 0
    for k in range(2):
        s = -1.0 if k == 0 else 1.0
        ph = phi + (math.pi if k == 0 else 0.0)
        hip_a = 0.42 * sw * math.sin(ph)
        knee = (0.08 + 0.75 * max(0.0, math.sin(ph + 1.3)) ** 2) * max(sw, 0.15)
        hx, hy = x0 + s * leg_x * lx, y0 + s * leg_x * ly
        joints[0, 0], joints[0, 1], joints[0, 2] = hx, hy, hip_z
        _limb(hx, hy, hip_z, fx, fy, hip_a, 0.245 * h, joints, 1)
        _limb(joints[1, 0], joints[1, 1], joints[1, 2], fx, fy, hip_a - knee, 0.25 * h, joints, 2)
        seg[n, 0], seg[n, 1], seg[n, 2] = joints[0, 0], joints[0, 1], joints[0, 2]
        seg[n, 3], seg[n, 4], seg[n, 5] = joints[1, 0], joints[1, 1], joints[1, 2]
        rad[n], col_idx[n] = 0.05 * h * bd, COL_PANTS
        n += 1
        seg[n, 0], seg[n, 1], seg[n, 2] = joints[1, 0], joints[1, 1], joints[1, 2]
        seg[n, 3], seg[n, 4], seg[n, 5] = joints[2, 0], joints[2, 1], joints[2, 2]
        rad[n], col_idx[n] = 0.037 * h * bd, shin_col
        n += 1
        foot = 0.11 * h
        az = max(joints[2, 2], 0.025 * h)
        seg[n, 0], seg[n, 1], seg[n, 2] = joints[2, 0] - 0.02 * h * fx, joints[2, 1] - 0.02 * h * fy, az
        seg[n, 3], seg[n, 4], seg[n, 5] = joints[2, 0] + foot * fx, joints[2, 1] + foot * fy, az - 0.01 * h
        rad[n], col_idx[n] = 0.024 * h, COL_SHOES
        n += 1
        arm_a = -0.32 * sw * math.sin(ph)
        elbow = 0.25 + 0.25 * sw * max(0.0, -math.sin(ph))
        sx_, sy_ = x0 + s * arm_x * lx, y0 + s * arm_x * ly
        szz = sh_z - 0.03 * h
        _limb(sx_, sy_, szz, fx, fy, arm_a, 0.175 * h, joints, 3)
        _limb(joints[3, 0], joints[3, 1], joints[3, 2], fx, fy, arm_a + elbow, 0.19 * h, joints, 4)
        seg[n, 0], seg[n, 1], seg[n, 2] = sx_, sy_, szz
        seg[n, 3], seg[n, 4], seg[n, 5] = joints[3, 0], joints[3, 1], joints[3, 2]
        rad[n], col_idx[n] = 0.036 * h * bd, COL_SHIRT
        n += 1
        seg[n, 0], seg[n, 1], seg[n, 2] = joints[3, 0], joints[3, 1], joints[3, 2]
        seg[n, 3], seg[n, 4], seg[n, 5] = joints[4, 0], joints[4, 1], joints[4, 2]
        rad[n], col_idx[n] = 0.029 * h, COL_SHIRT if act[P_SLEEVES] > 0 else COL_SKIN
        n += 1
        # hand: on from the wrist along the forearm, a little narrower than it
        hand = 0.055 / 0.19  # of the forearm (0.19 h): the hand reaches 0.055 h past the wrist
        seg[n, 0], seg[n, 1], seg[n, 2] = joints[4, 0], joints[4, 1], joints[4, 2]
        seg[n, 3] = joints[4, 0] + hand * (joints[4, 0] - joints[3, 0])
        seg[n, 4] = joints[4, 1] + hand * (joints[4, 1] - joints[3, 1])
        seg[n, 5] = joints[4, 2] + hand * (joints[4, 2] - joints[3, 2])
        rad[n], col_idx[n] = 0.024 * h, COL_SKIN
        n += 1
    bag = int(act[P_BAG_KIND])
    if bag == BAG_BACKPACK:  # on the back, from below the shoulders to the small of the back
        back = -(0.08 * h * bd + 0.055 * h)
        seg[n, 0], seg[n, 1], seg[n, 2] = x0 + back * fx, y0 + back * fy, sh_z - 0.09 * h
        seg[n, 3], seg[n, 4], seg[n, 5] = x0 + back * fx, y0 + back * fy, hip_z + 0.12 * h
        rad[n], col_idx[n] = 0.07 * h, COL_BAG
        n += 1
    elif bag == BAG_SHOULDER:  # hanging at the right hip, outside the swinging arm, longer along the walk
        side = arm_x + 0.05 * h
        bx, by, bz = x0 + side * lx, y0 + side * ly, hip_z + 0.04 * h
        seg[n, 0], seg[n, 1], seg[n, 2] = bx - 0.06 * h * fx, by - 0.06 * h * fy, bz
        seg[n, 3], seg[n, 4], seg[n, 5] = bx + 0.06 * h * fx, by + 0.06 * h * fy, bz
        rad[n], col_idx[n] = 0.05 * h, COL_BAG
        n += 1
    return n


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
