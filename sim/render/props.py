"""Numba kernels of the street props (parked cars, trees, lamp poles, signs, benches, bins): world boxes and parts.

A prop is a static actor (``TYPE_PROP`` in ``body``'s table) whose row holds its kind, footprint,
size and colours (columns below, filled by ``tables``); ``actors`` bounds and draws it
through the walkers' pipeline, so props hide walkers and the visibility truth counts it. Parts are capsules
(poles, trunks, bins, legs; spheres for canopies and wheels) and flat faces of axis-aligned boxes, clipped at the
camera's near plane (a camera driving past a parked car). Only the faces turned to the camera are drawn, so a
box's faces never overlap on the image; a car is split along its length into slices of its own rows, each
painted at its own depth, which keeps the one-depth-per-part painter's order right for a walker beside a long
car. Faces are lit flat: albedo x (ambient + sun x cos), the sun blocked by the canyon at the prop's height.
"""

from __future__ import annotations

import math

from numba import njit

from .._jitcache import guard
from .parts import (
    MAX_PARTS,
    N_VERTS,
    NEAR_M,
    PART_QUAD,
    Q_AMB,
    Q_DEPTH,
    Q_DIR,
    Q_GEO,
    Q_KIND,
    Q_LX,
    Q_LZ,
    Q_YMAX,
    Q_YMIN,
    capsule_part,
    sun_in_view,
)
from .world import C_CX, C_CY, C_FX, C_FY, C_TRANSPOSED, L_AMB, L_SUN, L_SUN_RGB, sun_blocked

# ---- prop rows of the actor table (after A_TYPE, A_STATIC, A_SPEED, A_ID) ----------------------------------
G_KIND, G_X, G_Y, G_L, G_W, G_H, G_DIR, G_RGB, G_RGB2, G_S0, G_S1, G_A, G_B, G_C = (
    4, 5, 6, 7, 8, 9, 10, 11, 14, 17, 18, 19, 20, 21)
"""Kind code; footprint centre x, y (a car slice: the car's); size along Y, X and up; facing sign; albedos (main,
second: windows, canopy, plate, lamp head, legs); a car slice's y range from the centre; three per-kind sizes
(car: body top, cabin start and end from the centre; tree: trunk radius, trunk height, canopy radius; pole:
radius, arm length; sign: plate size; bench: seat height; bin: radius)."""
PK_CAR, PK_TREE, PK_POLE, PK_SIGN, PK_BENCH, PK_BIN = 0, 1, 2, 3, 4, 5
PROP_CODES = {"car": PK_CAR, "tree": PK_TREE, "pole": PK_POLE, "sign": PK_SIGN, "bench": PK_BENCH, "bin": PK_BIN}
PROP_BOX = 6
WHEEL_R, CAR_FLOOR, AXLE_IN = 0.31, 0.30, 0.80  # wheel radius, body's underside, axle from each end (m)
CABIN_INSET = 0.08  # the cabin's sides stand in from the body's by this fraction of its width
BOX_MARGIN = 0.05  # world bounds' margin around capsules, m
AMB_SIDE = 0.75  # ambient on a vertical face (it sees half the sky) relative to a top face
TYRE_RGB = (0.035, 0.035, 0.04)


@njit(cache=True)
def prop_ref_y(act):
    """The y a prop's copies are chosen by (the street repeats along Y): one value for every slice of a car."""
    return act[G_Y]


@njit(cache=True)
def prop_box(act, shift, box):
    """World box (x0, x1, y0, y1, z0, z1) of a prop row drawn ``shift`` m along Y; returns its largest capsule
    radius (m), for the bounds' near-plane pad."""
    x, y, kind = act[G_X], act[G_Y] + shift, int(act[G_KIND])
    half_w, half_l, h = 0.5 * act[G_W], 0.5 * act[G_L], act[G_H]
    # Spheres (wheels, crowns) project inside their box's image; an elongated capsule's image (its radius at its
    # mean depth) may not, so the box grows by the radius of the capsules that are not spheres.
    if kind == PK_CAR:
        x0, x1, y0, y1 = x - half_w, x + half_w, y + act[G_S0] - WHEEL_R, y + act[G_S1] + WHEEL_R
        r_max, r_long = WHEEL_R, 0.0
    elif kind == PK_TREE:
        reach = 1.2 * act[G_C]  # crown clumps reach 0.5 + 0.65 of its radius out
        x0, x1, y0, y1 = x - reach, x + reach, y - reach, y + reach
        h = act[G_B] + 1.8 * act[G_C]
        r_max, r_long = act[G_C], act[G_A]
    elif kind == PK_POLE:
        tip = act[G_DIR] * (act[G_B] + 0.5)
        x0, x1, y0, y1 = x + min(tip, 0.0), x + max(tip, 0.0), y, y
        r_max = r_long = max(act[G_A], 0.09)
    else:  # sign, bench, bin: their footprint
        x0, x1, y0, y1 = x - half_w, x + half_w, y - half_l, y + half_l
        r_max = r_long = act[G_A] if kind == PK_BIN else 0.04
    m = BOX_MARGIN + r_long
    box[0], box[1], box[2], box[3], box[4], box[5] = x0 - m, x1 + m, y0 - m, y1 + m, -m, h + m
    return r_max


@njit(cache=True, inline="always")
def _corner(poly, i, rot, pos, x, y, z):
    dx, dy, dz = x - pos[0], y - pos[1], z - pos[2]
    poly[i, 0] = rot[0, 0] * dx + rot[0, 1] * dy + rot[0, 2] * dz
    poly[i, 1] = rot[1, 0] * dx + rot[1, 1] * dy + rot[1, 2] * dz
    poly[i, 2] = rot[2, 0] * dx + rot[2, 1] * dy + rot[2, 2] * dz


@njit(cache=True)
def _face(parts, p, poly, cam, rgb_r, rgb_g, rgb_b):
    """Write row ``p``: the flat face whose camera-frame corners are ``poly[0:4]`` (in order), clipped at the near
    plane, colour ``rgb``; returns the next free row (``p`` when nothing of it is in front)."""
    n = 0
    o = N_VERTS  # the clipped polygon goes to rows N_VERTS..: a quad cut by one plane keeps at most five corners
    for i in range(4):
        j = (i + 1) % 4
        zi, zj = poly[i, 2], poly[j, 2]
        if zi >= NEAR_M:
            poly[o + n, 0], poly[o + n, 1], poly[o + n, 2] = poly[i, 0], poly[i, 1], zi
            n += 1
        if (zi >= NEAR_M) != (zj >= NEAR_M):
            f = (NEAR_M - zi) / (zj - zi)
            poly[o + n, 0] = poly[i, 0] + f * (poly[j, 0] - poly[i, 0])
            poly[o + n, 1] = poly[i, 1] + f * (poly[j, 1] - poly[i, 1])
            poly[o + n, 2] = NEAR_M
            n += 1
    if n < 3 or p >= MAX_PARTS:
        return p
    fx, fy, cx, cy = cam[C_FX], cam[C_FY], cam[C_CX], cam[C_CY]
    g = Q_GEO
    depth, ymin, ymax = 0.0, 1e300, -1e300
    for v in range(N_VERTS):
        k = o + (v if v < n else 0)  # unused corners repeat the first (zero-length edges)
        u = fx * poly[k, 0] / poly[k, 2] + cx
        w = fy * poly[k, 1] / poly[k, 2] + cy
        if cam[C_TRANSPOSED] != 0.0:
            u, w = w, u
        parts[p, g + 2 * v], parts[p, g + 2 * v + 1] = u, w
        ymin, ymax = min(ymin, w), max(ymax, w)
        if v < n:
            depth += poly[k, 2]
    parts[p, Q_KIND] = PART_QUAD
    parts[p, Q_DEPTH] = depth / n
    parts[p, Q_AMB], parts[p, Q_AMB + 1], parts[p, Q_AMB + 2] = rgb_r, rgb_g, rgb_b
    parts[p, Q_DIR], parts[p, Q_DIR + 1], parts[p, Q_DIR + 2] = 0.0, 0.0, 0.0
    parts[p, Q_LX], parts[p, Q_LZ] = 0.0, 0.0
    parts[p, Q_YMIN], parts[p, Q_YMAX] = ymin, ymax
    return p + 1


@njit(cache=True, inline="always")
def _lit(act, c, light, lit, nx, ny, nz):
    """Flat radiance of the albedo in columns ``c``.. (G_RGB or G_RGB2) on a face of normal n: ambient plus the
    sun's cosine."""
    cos = max(0.0, nx * light[L_SUN] + ny * light[L_SUN + 1] + nz * light[L_SUN + 2]) * lit
    amb = 1.0 if nz > 0.0 else AMB_SIDE
    return (act[c] * (light[L_AMB] * amb + light[L_SUN_RGB] * cos),
            act[c + 1] * (light[L_AMB + 1] * amb + light[L_SUN_RGB + 1] * cos),
            act[c + 2] * (light[L_AMB + 2] * amb + light[L_SUN_RGB + 2] * cos))


@njit(cache=True)
def _box_faces(parts, p, poly, rot, pos, cam, act, c, light, lit, x0, x1, y0, y1, z0, z1, sides, ends, top):
    """The faces of the box [x0, x1] x [y0, y1] x [z0, z1] the camera sees, of albedo ``c``: an X side when
    ``sides``, a Y end when ``ends`` allows it (bit 1: the -Y end, bit 2: the +Y end), the top when ``top``."""
    px, py, pz = pos[0], pos[1], pos[2]
    if sides and (px > x1 or px < x0) and y1 > y0:
        xf, nx = (x1, 1.0) if px > x1 else (x0, -1.0)
        _corner(poly, 0, rot, pos, xf, y0, z0)
        _corner(poly, 1, rot, pos, xf, y1, z0)
        _corner(poly, 2, rot, pos, xf, y1, z1)
        _corner(poly, 3, rot, pos, xf, y0, z1)
        r, g, b = _lit(act, c, light, lit, nx, 0.0, 0.0)
        p = _face(parts, p, poly, cam, r, g, b)
    if (py < y0 and ends & 1) or (py > y1 and ends & 2):
        yf, ny = (y0, -1.0) if py < y0 else (y1, 1.0)
        _corner(poly, 0, rot, pos, x0, yf, z0)
        _corner(poly, 1, rot, pos, x1, yf, z0)
        _corner(poly, 2, rot, pos, x1, yf, z1)
        _corner(poly, 3, rot, pos, x0, yf, z1)
        r, g, b = _lit(act, c, light, lit, 0.0, ny, 0.0)
        p = _face(parts, p, poly, cam, r, g, b)
    if top and pz > z1 and y1 > y0:
        _corner(poly, 0, rot, pos, x0, y0, z1)
        _corner(poly, 1, rot, pos, x1, y0, z1)
        _corner(poly, 2, rot, pos, x1, y1, z1)
        _corner(poly, 3, rot, pos, x0, y1, z1)
        r, g, b = _lit(act, c, light, lit, 0.0, 0.0, 1.0)
        p = _face(parts, p, poly, cam, r, g, b)
    return p


@njit(cache=True)
def _capsule(parts, p, rot, pos, cam, alb, light, lit, lx, lz, ax, ay, az, bx, by, bz, rad):
    """Write row ``p``: the world capsule a-b of radius ``rad`` and albedo ``alb`` (an RGB tuple), shaded as a
    walker's limb is; returns the next free row."""
    if p >= MAX_PARTS:
        return p
    dx, dy, dz = ax - pos[0], ay - pos[1], az - pos[2]
    a0 = rot[0, 0] * dx + rot[0, 1] * dy + rot[0, 2] * dz
    a1 = rot[1, 0] * dx + rot[1, 1] * dy + rot[1, 2] * dz
    a2 = rot[2, 0] * dx + rot[2, 1] * dy + rot[2, 2] * dz
    dx, dy, dz = bx - pos[0], by - pos[1], bz - pos[2]
    b0 = rot[0, 0] * dx + rot[0, 1] * dy + rot[0, 2] * dz
    b1 = rot[1, 0] * dx + rot[1, 1] * dy + rot[1, 2] * dz
    b2 = rot[2, 0] * dx + rot[2, 1] * dy + rot[2, 2] * dz
    if capsule_part(parts, p, a0, a1, a2, b0, b1, b2, rad, alb[0], alb[1], alb[2], cam[C_FX], cam[C_FY],
                    cam[C_CX], cam[C_CY], cam[C_TRANSPOSED] != 0.0, light[L_AMB], light[L_AMB + 1],
                    light[L_AMB + 2], light[L_SUN_RGB] * lit, light[L_SUN_RGB + 1] * lit,
                    light[L_SUN_RGB + 2] * lit, lx, lz):
        return p + 1
    return p


@njit(cache=True)
def _car(parts, poly, rot, pos, cam, act, light, lit, x, y, lx, lz):
    """One slice of a parked car: body, cabin (side windows, windscreen or rear window, roof) and wheels."""
    hw, hl, h, zb = 0.5 * act[G_W], 0.5 * act[G_L], act[G_H], act[G_A]
    s0, s1, c0, c1 = y + act[G_S0], y + act[G_S1], y + act[G_B], y + act[G_C]
    x0, x1 = x - hw, x + hw
    first, last = act[G_S0] <= -hl + 1e-9, act[G_S1] >= hl - 1e-9
    ends = (1 if first else 0) | (2 if last else 0)
    p = _box_faces(parts, 0, poly, rot, pos, cam, act, G_RGB, light, lit, x0, x1, s0, s1, CAR_FLOOR, zb, True,
                   ends, False)
    # The body's top (bonnet, boot, and shoulders beside the cabin), then the narrower cabin standing on it:
    # seen from above, the cabin's faces are nearer, so they are painted after it.
    p = _box_faces(parts, p, poly, rot, pos, cam, act, G_RGB, light, lit, x0, x1, s0, s1, CAR_FLOOR, zb, False, 0,
                   True)
    k0, k1 = max(s0, c0), min(s1, c1)
    if k1 > k0:
        inset = CABIN_INSET * act[G_W]
        cabin_ends = (1 if s0 <= c0 else 0) | (2 if s1 >= c1 else 0)
        p = _box_faces(parts, p, poly, rot, pos, cam, act, G_RGB2, light, lit, x0 + inset, x1 - inset, k0, k1, zb,
                       h, True, cabin_ends, False)
        p = _box_faces(parts, p, poly, rot, pos, cam, act, G_RGB, light, lit, x0 + inset, x1 - inset, k0, k1, zb,
                       h, False, 0, True)
    for axle in (y - hl + AXLE_IN, y + hl - AXLE_IN):
        if s0 <= axle < s1:
            for side in (-1.0, 1.0):
                wx = x + side * (hw - WHEEL_R)
                p = _capsule(parts, p, rot, pos, cam, TYRE_RGB, light, lit, lx, lz, wx, axle, WHEEL_R,
                             wx, axle, WHEEL_R, WHEEL_R)
    return p


@njit(cache=True)
def prop_parts(act, shift, world, lut, bld, light, cam, rot, pos, parts, poly):
    """Fill ``parts`` with the render-space primitives of a prop row drawn ``shift`` m along Y (rows left unused
    stay PART_NONE); ``poly`` is (2 N_VERTS x 3) scratch."""
    kind = int(act[G_KIND])
    x, y, h, d = act[G_X], act[G_Y] + shift, act[G_H], act[G_DIR]
    lx, lz = sun_in_view(rot, light, cam[C_TRANSPOSED] != 0.0)
    z_sun = act[G_A] if kind == PK_CAR else (act[G_B] + act[G_C] if kind == PK_TREE else 0.5 * h)
    lit = 0.0 if sun_blocked(world, lut, bld, x, y, z_sun, light, -1) else 1.0
    main = (act[G_RGB], act[G_RGB + 1], act[G_RGB + 2])
    second = (act[G_RGB2], act[G_RGB2 + 1], act[G_RGB2 + 2])
    if kind == PK_CAR:
        _car(parts, poly, rot, pos, cam, act, light, lit, x, y, lx, lz)
    elif kind == PK_TREE:
        rt, ht, rc = act[G_A], act[G_B], act[G_C]
        zc = ht + 0.8 * rc
        p = _capsule(parts, 0, rot, pos, cam, main, light, lit, lx, lz, x, y, rt, x, y, zc, rt)
        p = _capsule(parts, p, rot, pos, cam, second, light, lit, lx, lz, x, y, zc, x, y, zc, rc)
        for i in range(3):  # three smaller clumps around the crown, turned by the tree's own angle
            a = d + 2.0 * math.pi * i / 3.0
            cx_, cy_ = x + 0.5 * rc * math.cos(a), y + 0.5 * rc * math.sin(a)
            p = _capsule(parts, p, rot, pos, cam, second, light, lit, lx, lz, cx_, cy_, zc - 0.25 * rc,
                         cx_, cy_, zc - 0.25 * rc, 0.65 * rc)
    elif kind == PK_POLE:
        r, arm = act[G_A], act[G_B]
        p = _capsule(parts, 0, rot, pos, cam, main, light, lit, lx, lz, x, y, r, x, y, h, r)
        p = _capsule(parts, p, rot, pos, cam, main, light, lit, lx, lz, x, y, h, x + d * arm, y, h, 0.6 * r)
        p = _capsule(parts, p, rot, pos, cam, second, light, lit, lx, lz, x + d * arm, y, h - 0.04,
                     x + d * (arm + 0.5), y, h - 0.04, 0.09)
    elif kind == PK_SIGN:
        s = act[G_A]
        p = _capsule(parts, 0, rot, pos, cam, main, light, lit, lx, lz, x, y, 0.04, x, y, h - 0.05, 0.04)
        yp = y + d * 0.05  # the plate, in front of its pole; its back is the pole's grey
        front = (pos[1] - yp) * d > 0.0
        _corner(poly, 0, rot, pos, x - 0.5 * s, yp, h - s)
        _corner(poly, 1, rot, pos, x + 0.5 * s, yp, h - s)
        _corner(poly, 2, rot, pos, x + 0.5 * s, yp, h)
        _corner(poly, 3, rot, pos, x - 0.5 * s, yp, h)
        r, g, b = _lit(act, G_RGB2 if front else G_RGB, light, lit, 0.0, d if front else -d, 0.0)
        _face(parts, p, poly, cam, r, g, b)
    elif kind == PK_BENCH:
        hw, hl, zs = 0.5 * act[G_W], 0.5 * act[G_L], act[G_A]
        # Seat (a slab), backrest (a board on the side away from ``d``, the way the bench faces), two legs.
        p = _box_faces(parts, 0, poly, rot, pos, cam, act, G_RGB, light, lit, x - hw, x + hw, y - hl, y + hl,
                       zs - 0.06, zs, True, 3, True)
        xb = x - d * hw
        _corner(poly, 0, rot, pos, xb, y - hl, zs)
        _corner(poly, 1, rot, pos, xb, y + hl, zs)
        _corner(poly, 2, rot, pos, xb, y + hl, h)
        _corner(poly, 3, rot, pos, xb, y - hl, h)
        r, g, b = _lit(act, G_RGB, light, lit, d if (pos[0] - xb) * d > 0.0 else -d, 0.0, 0.0)
        p = _face(parts, p, poly, cam, r, g, b)
        for sy in (-1.0, 1.0):
            ly = y + sy * (hl - 0.15)
            p = _capsule(parts, p, rot, pos, cam, second, light, lit, lx, lz, x, ly, 0.04, x, ly, zs - 0.06,
                         0.04)
    else:  # bin: a rounded drum
        r = act[G_A]
        _capsule(parts, 0, rot, pos, cam, main, light, lit, lx, lz, x, y, r, x, y, h - r, r)


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
