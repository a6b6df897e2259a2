"""The part table the render kernels share: one actor's render-space primitives at one time, and the capsule
writer every kind of actor uses.

``actors`` fills it for walkers and chart bars and ``props`` for street props; the line
kernels of ``lines`` intersect and paint it. A row is a capsule (end points and a radius from
``Q_GEO``, shaded as a cylinder across its span by ``Q_LX``/``Q_LZ``) or a convex polygon of up to ``N_VERTS``
vertices (flat: with ``Q_LX = Q_LZ = 0`` its colour is ``Q_AMB``); a quad repeats its first vertex as the fifth,
which a near-plane clip of a quad may need. A shadow (``shadow_part``, ``ground_shadow``) is an ellipse on the
image, centre and inverse shape matrix from ``Q_GEO``, strengths in ``Q_AMB``, edge in ``Q_DIR``: it darkens
what lies under it instead of hiding it, and is no part of its actor's extent or visibility.
``Q_YMIN``..``Q_YMAX`` is the range of lines the part can reach.
"""

from __future__ import annotations

import math

from numba import njit

from .._jitcache import guard
from .world import C_CX, C_CY, C_FX, C_FY, C_TRANSPOSED, L_SUN

Q_KIND, Q_DEPTH, Q_AMB, Q_DIR, Q_LX, Q_LZ, Q_GEO = 0, 1, 2, 5, 8, 9, 10
N_VERTS = 5
Q_YMIN, Q_YMAX = Q_GEO + 2 * N_VERTS, Q_GEO + 2 * N_VERTS + 1
Q_TEX, Q_TEXK, Q_TSEED = Q_YMAX + 1, Q_YMAX + 2, Q_YMAX + 3
"""Surface texture of a capsule (``lines._texture``): contrast (0: none), lattice cells per pixel,
seed."""
Q_FACE, Q_HAIR = Q_TSEED + 1, Q_TSEED + 3
"""A head's face: the direction it looks, (cos, sin) of its angle from the camera (cos < -1: no face), and the
hair's albedo over the skin's per channel (hairline, brows)."""
PART_COLS = Q_HAIR + 3
MAX_PARTS = 21  # a walker's 18 capsules, its bag, its contact shadow and its sun shadow
PART_CAPSULE, PART_QUAD, PART_SHADOW, PART_NONE = 0, 1, 2, -1
NEAR_M = 0.05
"""The camera's near plane, m: parts are clipped there so parts crossing the camera plane stay finite."""


@njit(cache=True, inline="always")
def sun_in_view(rot, light, transposed):
    """The sun seen from pose ``rot`` for cylinder shading: (image-plane x along the line, viewing-axis z)."""
    sx = rot[0, 0] * light[L_SUN] + rot[0, 1] * light[L_SUN + 1] + rot[0, 2] * light[L_SUN + 2]
    sz = -(rot[2, 0] * light[L_SUN] + rot[2, 1] * light[L_SUN + 1] + rot[2, 2] * light[L_SUN + 2])
    sy_up = light[L_SUN + 2]
    nrm = math.sqrt(sx * sx + sz * sz) + 1e-12
    horiz = math.sqrt(max(0.0, 1.0 - sy_up * sy_up))
    lxv, lzv = sx / nrm * horiz, sz / nrm * horiz
    return (0.0 if transposed else lxv), lzv  # a transposed line runs along the image's y axis


@njit(cache=True, inline="always")
def capsule_part(parts, p, a0, a1, a2, b0, b1, b2, rad, alb_r, alb_g, alb_b, fx, fy, cx, cy, transposed,
                 amb_r, amb_g, amb_b, sun_r, sun_g, sun_b, lx_part, lzv):
    """Write row ``p``: the capsule from camera-frame ``a`` to ``b`` of radius ``rad`` m, albedo ``alb``, under
    ambient ``amb`` and (already shadowed) sun ``sun``; False (row untouched) when wholly behind the near plane.

    Scalars, not arrays: an array handed to a helper is reference-counted per call, which on an RS frame (parts
    recomputed on every line an actor touches) cost more than the arithmetic.
    """
    if a2 < NEAR_M and b2 < NEAR_M:
        return False
    # Clip the segment at the near plane so parts crossing the camera plane stay finite.
    if a2 < NEAR_M:
        f = (NEAR_M - a2) / (b2 - a2)
        a0, a1, a2 = a0 + f * (b0 - a0), a1 + f * (b1 - a1), a2 + f * (b2 - a2)
    elif b2 < NEAR_M:
        f = (NEAR_M - b2) / (a2 - b2)
        b0, b1, b2 = b0 + f * (a0 - b0), b1 + f * (a1 - b1), b2 + f * (a2 - b2)
    zm = 0.5 * (a2 + b2)
    ua0, ua1 = fx * a0 / a2 + cx, fy * a1 / a2 + cy
    ub0, ub1 = fx * b0 / b2 + cx, fy * b1 / b2 + cy
    if transposed:
        ua0, ua1, ub0, ub1 = ua1, ua0, ub1, ub0
    r_px = fx * rad / zm
    parts[p, Q_KIND] = PART_CAPSULE
    parts[p, Q_DEPTH] = zm
    parts[p, Q_AMB], parts[p, Q_AMB + 1], parts[p, Q_AMB + 2] = alb_r * amb_r, alb_g * amb_g, alb_b * amb_b
    parts[p, Q_DIR], parts[p, Q_DIR + 1], parts[p, Q_DIR + 2] = alb_r * sun_r, alb_g * sun_g, alb_b * sun_b
    parts[p, Q_LX], parts[p, Q_LZ] = lx_part, lzv
    g = Q_GEO
    parts[p, g], parts[p, g + 1], parts[p, g + 2], parts[p, g + 3] = ua0, ua1, ub0, ub1
    parts[p, g + 4] = r_px
    parts[p, Q_YMIN] = min(ua1, ub1) - r_px
    parts[p, Q_YMAX] = max(ua1, ub1) + r_px
    return True


SHADOW_DEPTH = 1e30
"""A shadow's depth in the painter's order: farthest, so it darkens only the background (the ground it lies
on) and every actor is painted over it: where an actor is seen, the ground on that ray lies behind it."""


@njit(cache=True, inline="always")
def shadow_part(parts, p, cu, cv, pu, pv, qu, qv, s_r, s_g, s_b, edge):
    """Write row ``p``: a shadow, the ellipse ``c + P cos t + Q sin t`` of centre ``c`` and conjugate
    semi-diameters ``P``, ``Q`` (render space: a ground ellipse's centre and axis ends, projected). What lies
    under it keeps ``1 - s min(1, edge (1 - r^2))^2`` of its light per channel, ``s`` = (``s_r``, ``s_g``,
    ``s_b``) and r the elliptical radius: ``edge`` 1 fades from the centre, larger gives a flat core and a
    rim that fades over the outer 1 / edge of r^2. ``Q_GEO`` holds the centre and the inverse of [P Q] (a
    pixel's r is the length of that matrix times its offset from the centre), ``Q_AMB`` the strengths and
    ``Q_DIR`` the edge."""
    det = pu * qv - qu * pv
    if abs(det) < 1e-9:
        return
    parts[p, Q_KIND] = PART_SHADOW
    parts[p, Q_DEPTH] = SHADOW_DEPTH
    parts[p, Q_AMB], parts[p, Q_AMB + 1], parts[p, Q_AMB + 2] = s_r, s_g, s_b
    parts[p, Q_DIR], parts[p, Q_DIR + 1], parts[p, Q_DIR + 2] = edge, 0.0, 0.0
    parts[p, Q_LX], parts[p, Q_LZ] = 0.0, 0.0
    g = Q_GEO
    parts[p, g], parts[p, g + 1] = cu, cv
    parts[p, g + 2], parts[p, g + 3] = qv / det, -qu / det
    parts[p, g + 4], parts[p, g + 5] = -pv / det, pu / det
    half = math.sqrt(pv * pv + qv * qv)
    parts[p, Q_YMIN], parts[p, Q_YMAX] = cv - half, cv + half


@njit(cache=True)
def ground_shadow(parts, p, x, y, ax, ay, bx, by, s_r, s_g, s_b, edge, cam, rot, pos):
    """Row ``p``: a shadow on the ground, the ellipse of centre (x, y) and semi-axes (ax, ay), (bx, by) (world
    m), seen as the image ellipse its projected centre and axis ends span, shrunk where perspective would take
    it past the image box of its world rectangle (which lies in the walker's bounds box: so the shadow is drawn
    on every line it reaches, on every path); none when that box reaches behind the camera or would shrink it
    below half. Strength per channel and edge sharpness as ``shadow_part``'s."""
    cu, cv, pu, pv, qu, qv = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    u_lo, u_hi, v_lo, v_hi = 1e300, -1e300, 1e300, -1e300
    for k in range(7):  # centre, the two axis ends, then the rectangle's four corners
        sa = 1.0 if k == 1 or k == 3 or k == 4 else -1.0 if k == 5 or k == 6 else 0.0
        sb = 1.0 if k == 2 or k == 3 or k == 5 else -1.0 if k == 4 or k == 6 else 0.0
        dx = x + sa * ax + sb * bx - pos[0]
        dy = y + sa * ay + sb * by - pos[1]
        dz = -pos[2]
        cz = rot[2, 0] * dx + rot[2, 1] * dy + rot[2, 2] * dz
        if cz < NEAR_M:
            return  # reaching behind the camera: no shadow drawn
        u = cam[C_FX] * (rot[0, 0] * dx + rot[0, 1] * dy + rot[0, 2] * dz) / cz + cam[C_CX]
        v = cam[C_FY] * (rot[1, 0] * dx + rot[1, 1] * dy + rot[1, 2] * dz) / cz + cam[C_CY]
        if cam[C_TRANSPOSED] != 0.0:
            u, v = v, u
        if k == 0:
            cu, cv = u, v
        elif k == 1:
            pu, pv = u - cu, v - cv
        elif k == 2:
            qu, qv = u - cu, v - cv
        else:
            u_lo, u_hi, v_lo, v_hi = min(u_lo, u), max(u_hi, u), min(v_lo, v), max(v_hi, v)
    hu, hv = math.hypot(pu, qu), math.hypot(pv, qv)  # the ellipse's half extents
    f = min(1.0, (cu - u_lo) / max(hu, 1e-12), (u_hi - cu) / max(hu, 1e-12), (cv - v_lo) / max(hv, 1e-12),
            (v_hi - cv) / max(hv, 1e-12))
    if f < 0.5:
        return
    f *= 1.0 - 1e-9  # strictly inside, whatever the rounding of the extents
    shadow_part(parts, p, cu, cv, f * pu, f * pv, f * qu, f * qv, s_r, s_g, s_b, edge)


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
