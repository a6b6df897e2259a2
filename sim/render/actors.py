"""Numba kernels of the renderer's actors: render-space bounds, parts and image speeds of walkers, chart bars and
street props.

The walker model is ``body``, the props' ``props``, camera poses and the street's
shading ``world``; the line kernels of ``lines`` intersect and paint the parts these
functions produce, whose table (one actor at one time) is laid out in ``parts``. Every function is
pure, so every render path draws identical parts.
Render space as in ``lines``: a transposed camera (column readout) swaps x and y.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .._jitcache import guard
from .body import (
    A_ID,
    A_TYPE,
    COL_BAG,
    P_BAG,
    P_BUILD,
    P_CAST_S,
    P_CAST_X,
    P_CAST_Y,
    P_H,
    P_HAIR,
    P_SHADOW,
    P_SKIN,
    P_SPEED,
    R_PERIOD,
    R_RGB,
    R_VX,
    R_WIDTH,
    R_X0,
    TYPE_BAR,
    TYPE_PROP,
    pedestrian_root,
    pedestrian_skeleton,
)
from .parts import (
    MAX_PARTS,
    N_VERTS,
    NEAR_M,
    PART_CAPSULE,
    PART_COLS,
    PART_NONE,
    PART_QUAD,
    Q_AMB,
    Q_DEPTH,
    Q_DIR,
    Q_FACE,
    Q_GEO,
    Q_HAIR,
    Q_KIND,
    Q_LX,
    Q_LZ,
    Q_TEX,
    Q_TEXK,
    Q_TSEED,
    Q_YMAX,
    Q_YMIN,
    capsule_part,
    ground_shadow,
    sun_in_view,
)
from .props import PROP_BOX, prop_box, prop_parts, prop_ref_y
from .world import (
    C_CX,
    C_CY,
    C_FX,
    C_FY,
    C_H,
    C_TRANSPOSED,
    C_W,
    KIND_STREET,
    L_AMB,
    L_SUN_RGB,
    W_KIND,
    W_YHALF,
    sun_blocked,
    to_camera,
)

# Surface texture per material (``COL_*``: skin, hair, shirt, pants, shoes, bag): contrast of the albedo's
# variation and the size of its features on the body, m. Cloth folds and weave, hair strands, skin: what makes a
# photographed person's surface vary, which detectors trained on photographs key on (benchmarks/realism.py
# measures it). A bag is nylon or leather with seams and pockets: coarser than cloth, less contrast.
TEX_CONTRAST = (0.10, 0.45, 0.40, 0.40, 0.25, 0.30)
TEX_CELL_M = (0.05, 0.02, 0.07, 0.07, 0.04, 0.10)
NO_FACE = -2.0
"""``Q_FACE`` of a part that is not a head."""


@njit(cache=True, inline="always")
def _face_dir(parts, fx, fy, fz, vx, vy, vz):
    """Store in head row 0 the (cos, sin) of its face's angle from the camera: ``f`` is the walker's heading and
    ``v`` the head's position, both in the camera frame; sin > 0 turns the face to the image's right."""
    nv = math.sqrt(vx * vx + vy * vy + vz * vz)
    vx, vy, vz = vx / nv, vy / nv, vz / nv
    c = -(fx * vx + fy * vy + fz * vz)  # 1: looking straight into the camera
    s = fx - (fx * vx + fy * vy + fz * vz) * vx  # the heading's image-horizontal part, across the view ray
    n = math.sqrt(c * c + s * s)
    parts[0, Q_FACE], parts[0, Q_FACE + 1] = (c / n, s / n) if n > 0.0 else (0.0, 1.0)
BODY_LATERAL, BODY_FORWARD, BODY_TOP = 0.25, 0.40, 1.02  # walker bounds, fractions of height (see actor_bounds)
PART_RADIUS_MAX = 0.1  # walker part radii, fraction of height x build (the largest in body: a skirt's 0.095)
N_CHUNKS = 16  # parallel work units; scratch buffers are allocated once per unit, not per item


TEX_SEED_PARTS = 18
"""Texture seeds are actor id x this + part (the part count when they were made: the look stays the same)."""
SHADOW_SIDE, SHADOW_ALONG = 0.14, 0.2
"""A contact shadow's semi-axes on the ground: across the walk as a fraction of the walker's width (its height x
build), along it as a fraction of its height (the feet's reach; both inside BODY_LATERAL and BODY_FORWARD)."""
CAST_SIDE, CAST_FOOT, CAST_EDGE = 0.13, 0.08, 3.0
"""The sun's shadow of a walker: an ellipse from its feet to where the sun puts its head's shadow, as wide as
CAST_SIDE x its width either side, reaching CAST_FOOT x its height past both ends, with a dark core and a
soft rim (CAST_EDGE: see ``shadow_part``)."""


@njit(cache=True, inline="always")
def _project(cam, x, y, z, out):
    """Camera-frame point to render-space pixel coordinates (x, y swapped when transposed)."""
    u = cam[C_FX] * x / z + cam[C_CX]
    v = cam[C_FY] * y / z + cam[C_CY]
    if cam[C_TRANSPOSED] != 0.0:
        out[0], out[1] = v, u
    else:
        out[0], out[1] = u, v


@njit(cache=True, inline="always")
def _lane_shift(world, pos, y):
    """Street-period shift that brings a walker at ``y`` to its copy nearest the camera.

    The street repeats every ``length`` along Y (facades wrap), and so does the crowd: a camera travelling
    down the street keeps meeting walkers instead of leaving them behind. Copies swap half a period away.
    """
    if world[W_KIND] != KIND_STREET:
        return 0.0
    period = 2.0 * world[W_YHALF]
    return period * math.floor((pos[1] - y) / period + 0.5)


@njit(cache=True)
def actor_bounds(act, world, cam, rot, pos, t, dt, out, root, pc, uv):
    """Conservative render-space box (ymin, ymax, xmin, xmax) of an actor over times [t, t + dt].

    ``rot, pos`` is the camera pose, which must hold over the whole interval (dt = 0 for a moving camera).
    Empty when ymin > ymax.
    """
    out[0], out[1], out[2], out[3] = 1e30, -1e30, 1e30, -1e30
    typ = int(act[A_TYPE])
    if typ == TYPE_BAR:
        x0 = _bar_x0(act, t)
        xs0, xs1 = x0, x0 + act[R_WIDTH]
        big = 1e6
        if dt > 0.0:
            xs0, xs1 = -big, big  # may wrap within the interval
        if cam[C_TRANSPOSED] != 0.0:
            out[0], out[1], out[2], out[3] = xs0, xs1, -big, big
        else:
            out[0], out[1], out[2], out[3] = -big, big, xs0, xs1
        return
    if typ == TYPE_PROP:
        box = np.empty(PROP_BOX)
        r_max = prop_box(act, _lane_shift(world, pos, prop_ref_y(act)), box)
        box_bounds(cam, rot, pos, box[0], box[1], box[2], box[3], box[4], box[5], cam[C_FX] * r_max / NEAR_M,
                   out, pc, uv)
        return
    pedestrian_root(act, t, root)
    root[1] += _lane_shift(world, pos, root[1])
    h = act[P_H]
    # Body reach from the root, with margin: arms and hips at most 0.18 h x build sideways, feet and hands
    # at most 0.32 h forward or back, head top at 1.007 h (tests/test_render.py checks the containment).
    lat = BODY_LATERAL * h * max(act[P_BUILD], 1.0)
    ey = BODY_FORWARD * h + abs(act[P_SPEED]) * dt  # walkers move along Y only, at most speed * dt either way
    pad = cam[C_FX] * PART_RADIUS_MAX * h * max(act[P_BUILD], 1.0) / NEAR_M
    # Feet dip a little below the ground plane; the sun's shadow reaches out along the ground.
    x0, x1, y0, y1 = root[0] - lat, root[0] + lat, root[1] - ey, root[1] + ey
    cx, cy = act[P_CAST_X] * h, act[P_CAST_Y] * h
    x0, x1, y0, y1 = min(x0, x0 + cx), max(x1, x1 + cx), min(y0, y0 + cy), max(y1, y1 + cy)
    box_bounds(cam, rot, pos, x0, x1, y0, y1, -0.02 * h, BODY_TOP * h, pad, out, pc, uv)


@njit(cache=True)
def box_bounds(cam, rot, pos, x0, x1, y0, y1, z0, z1, pad_px, out, pc, uv):
    """Render-space box (ymin, ymax, xmin, xmax) of the world box [x0, x1] x [y0, y1] x [z0, z1] seen from
    (rot, pos), for parts inside it whose pixel radius is at most ``pad_px`` at the near plane."""
    out[0], out[1], out[2], out[3] = 1e30, -1e30, 1e30, -1e30
    n_behind = 0
    corners = np.empty((8, 3))
    for i in range(8):
        x = x1 if i & 1 else x0
        y = y1 if i & 2 else y0
        z = z1 if i & 4 else z0
        to_camera(rot, pos, x, y, z, pc)
        corners[i, 0], corners[i, 1], corners[i, 2] = pc[0], pc[1], pc[2]
        if pc[2] < NEAR_M:
            n_behind += 1
            continue
        _project(cam, pc[0], pc[1], pc[2], uv)
        out[2], out[3] = min(out[2], uv[0]), max(out[3], uv[0])
        out[0], out[1] = min(out[0], uv[1]), max(out[1], uv[1])
    if n_behind == 8:
        out[0], out[1] = 1e30, -1e30
    elif n_behind > 0:
        # Straddles the camera plane. Parts are clipped at the near plane, so what can be drawn lies in the box
        # cut there: a convex solid whose vertices are the corners in front (projected above) and the points
        # where box edges cross the plane, and whose image is the hull of theirs. A part's pixel radius
        # (fx * r / its mean depth, at least NEAR_M) can exceed that hull near the plane: pad by the largest.
        for i in range(8):
            for bit in (1, 2, 4):
                j = i ^ bit
                za, zb = corners[i, 2], corners[j, 2]
                if j < i or (za < NEAR_M) == (zb < NEAR_M):
                    continue
                f = (NEAR_M - za) / (zb - za)
                _project(cam, corners[i, 0] + f * (corners[j, 0] - corners[i, 0]),
                         corners[i, 1] + f * (corners[j, 1] - corners[i, 1]), NEAR_M, uv)
                out[2], out[3] = min(out[2], uv[0]), max(out[3], uv[0])
                out[0], out[1] = min(out[0], uv[1]), max(out[1], uv[1])
        out[0], out[1], out[2], out[3] = out[0] - pad_px, out[1] + pad_px, out[2] - pad_px, out[3] + pad_px


@njit(cache=True, inline="always")
def _bar_x0(act, t):
    period = act[R_PERIOD]
    x = act[R_X0] + act[R_VX] * t
    if period > 0.0:
        # Wrap inside [-pitch, period - pitch): off-image on both sides, so wrapping is never seen.
        x = (x + act[R_WIDTH] + 1.0) % period - act[R_WIDTH] - 1.0
    return x


@njit(cache=True)
def _set_quad(parts, p, x0, y0, x1, y1, x2, y2, x3, y3):
    g = Q_GEO
    parts[p, g], parts[p, g + 1], parts[p, g + 2], parts[p, g + 3] = x0, y0, x1, y1
    parts[p, g + 4], parts[p, g + 5], parts[p, g + 6], parts[p, g + 7] = x2, y2, x3, y3
    parts[p, g + 8], parts[p, g + 9] = x0, y0  # a quad's fifth vertex is its first (see rollcam.sim.render.parts)
    parts[p, Q_YMIN] = min(min(y0, y1), min(y2, y3))
    parts[p, Q_YMAX] = max(max(y0, y1), max(y2, y3))


@njit(cache=True)
def actor_parts(act, world, lut, bld, light, cam, rot, pos, t, parts, scratch):
    """Fill ``parts`` (MAX_PARTS x PART_COLS) with the render-space primitives of an actor at time ``t``."""
    seg, rad, col_idx, root, joints, poly = scratch
    for p in range(MAX_PARTS):
        parts[p, Q_KIND] = PART_NONE
        for q in range(Q_TEX, PART_COLS):  # no texture and no face unless a walker's capsule sets them
            parts[p, q] = 0.0
        parts[p, Q_FACE] = NO_FACE
    typ = int(act[A_TYPE])
    if typ == TYPE_PROP:
        prop_parts(act, _lane_shift(world, pos, prop_ref_y(act)), world, lut, bld, light, cam, rot, pos, parts, poly)
        return
    if typ == TYPE_BAR:
        x0 = _bar_x0(act, t)
        x1 = x0 + act[R_WIDTH]
        big = 1e6
        parts[0, Q_KIND] = PART_QUAD
        parts[0, Q_DEPTH] = 1.0
        for c in range(3):
            parts[0, Q_AMB + c] = act[R_RGB + c]
            parts[0, Q_DIR + c] = 0.0
        parts[0, Q_LX], parts[0, Q_LZ] = 0.0, 0.0
        if cam[C_TRANSPOSED] != 0.0:
            _set_quad(parts, 0, -big, x0, big, x0, big, x1, -big, x1)
        else:
            _set_quad(parts, 0, x0, -big, x1, -big, x1, big, x0, big)
        return
    n = pedestrian_skeleton(act, t, seg, rad, col_idx, root, joints)
    shift = _lane_shift(world, pos, root[1])
    if shift != 0.0:
        root[1] += shift
        for p in range(n):
            seg[p, 1] += shift
            seg[p, 4] += shift
    # Sun on the walker: blocked by the street canyon at chest height.
    lit = 0.0 if sun_blocked(world, lut, bld, root[0], root[1], 0.7 * act[P_H], light, -1) else 1.0
    # Pose, intrinsics and lights as scalars (see ``capsule_part``). Every expression keeps ``to_camera``'s and
    # ``_project``'s operation order, so the parts are bit-identical.
    r00, r01, r02 = rot[0, 0], rot[0, 1], rot[0, 2]
    r10, r11, r12 = rot[1, 0], rot[1, 1], rot[1, 2]
    r20, r21, r22 = rot[2, 0], rot[2, 1], rot[2, 2]
    p0, p1, p2 = pos[0], pos[1], pos[2]
    fx, fy, cx, cy = cam[C_FX], cam[C_FY], cam[C_CX], cam[C_CY]
    transposed = cam[C_TRANSPOSED] != 0.0
    amb_r, amb_g, amb_b = light[L_AMB], light[L_AMB + 1], light[L_AMB + 2]
    sun_r, sun_g, sun_b = light[L_SUN_RGB] * lit, light[L_SUN_RGB + 1] * lit, light[L_SUN_RGB + 2] * lit
    lx_part, lzv = sun_in_view(rot, light, transposed)
    for p in range(n):
        dx, dy, dz = seg[p, 0] - p0, seg[p, 1] - p1, seg[p, 2] - p2
        a0 = r00 * dx + r01 * dy + r02 * dz
        a1 = r10 * dx + r11 * dy + r12 * dz
        a2 = r20 * dx + r21 * dy + r22 * dz
        dx, dy, dz = seg[p, 3] - p0, seg[p, 4] - p1, seg[p, 5] - p2
        b0 = r00 * dx + r01 * dy + r02 * dz
        b1 = r10 * dx + r11 * dy + r12 * dz
        b2 = r20 * dx + r21 * dy + r22 * dz
        base = P_BAG if col_idx[p] == COL_BAG else P_SKIN + 3 * col_idx[p]
        if capsule_part(parts, p, a0, a1, a2, b0, b1, b2, rad[p], act[base], act[base + 1], act[base + 2],
                        fx, fy, cx, cy, transposed, amb_r, amb_g, amb_b, sun_r, sun_g, sun_b, lx_part, lzv):
            ci, r_px = col_idx[p], parts[p, Q_GEO + 4]
            parts[p, Q_TEX] = TEX_CONTRAST[ci]
            parts[p, Q_TEXK] = rad[p] / (r_px * TEX_CELL_M[ci]) if r_px > 0.0 else 0.0  # cells per pixel
            parts[p, Q_TSEED] = act[A_ID] * TEX_SEED_PARTS + p
            if p == 0:  # the head: which way its face looks, seen from the camera
                _face_dir(parts, r01 * root[2], r11 * root[2], r21 * root[2], a0 + b0, a1 + b1, a2 + b2)
                for c in range(3):
                    parts[p, Q_HAIR + c] = act[P_HAIR + c] / max(act[P_SKIN + c], 1e-6)
    if act[P_SHADOW] > 0.0 and n + 1 < MAX_PARTS:
        width = act[P_H] * max(act[P_BUILD], 1.0)
        s = act[P_SHADOW]
        ground_shadow(parts, n, root[0], root[1], SHADOW_SIDE * width, 0.0, 0.0, SHADOW_ALONG * act[P_H],
                       s, s, s, 1.0, cam, rot, pos)
        cx, cy = act[P_CAST_X] * act[P_H], act[P_CAST_Y] * act[P_H]
        reach = math.hypot(cx, cy)
        if lit > 0.0 and reach > 0.0:
            ux, uy = cx / reach, cy / reach
            gx, gy = root[0] + 0.5 * cx, root[1] + 0.5 * cy
            if not sun_blocked(world, lut, bld, gx, gy, 0.05, light, -1):  # not in a facade's shadow
                along, side = 0.5 * reach + CAST_FOOT * act[P_H], CAST_SIDE * width
                ground_shadow(parts, n + 1, gx, gy, -uy * side, ux * side, ux * along, uy * along,
                               act[P_CAST_S], act[P_CAST_S + 1], act[P_CAST_S + 2], CAST_EDGE, cam, rot, pos)


@njit(cache=True, inline="always")
def _clamped(v, lo, hi):
    return min(max(v, lo), hi)


@njit(cache=True, nogil=True)
def actor_speeds(actors, world, lut, bld, light, cam, rot_tab, pos_tab, times, need, out, part_rate, part_y):
    """out[o] = fastest render-space displacement rate (px/s) of any part end point of actor o, where
    ``need[o]`` (0 elsewhere: an actor no line of the frame can see needs no speed).

    Per part p the same over the times: ``part_rate[o, p]`` its own fastest rate (-1 where the part changes kind
    between two times, so its motion is not measured: use the actor's), ``part_y[o, p]`` the lowest
    ``Q_YMIN`` and highest ``Q_YMAX`` it has at any of them (the render lines it reaches; (inf, -inf) when it
    never shows). Only needed actors' rows are written.

    Parts wholly off the image (beyond half its size) at both times cannot move a pixel and are skipped;
    end points are clamped to that margin, so a part clipped at the camera's near plane (whose clipped end
    point races across image space far outside the frame) counts only its motion near the image.
    """
    _speeds_chunk(0, 1, actors, world, lut, bld, light, cam, rot_tab, pos_tab, times, need, out, part_rate, part_y)


@njit(cache=True, parallel=True, nogil=True)
def actor_speeds_par(actors, world, lut, bld, light, cam, rot_tab, pos_tab, times, need, out, part_rate, part_y):
    """``actor_speeds`` over the numba threads, an actor a work unit (worth their start-up for many actors
    and times)."""
    idx = np.flatnonzero(need)
    for j in prange(idx.shape[0]):  # unit idx[j] of n_obj: that actor alone
        _speeds_chunk(idx[j], actors.shape[0], actors, world, lut, bld, light, cam, rot_tab, pos_tab, times, need,
                      out, part_rate, part_y)


@njit(cache=True)
def _speeds_chunk(ch, n_chunks, actors, world, lut, bld, light, cam, rot_tab, pos_tab, times, need, out, part_rate,
                  part_y):
    """Work unit ``ch`` of ``n_chunks`` of ``actor_speeds``: the needed actors ch, ch + n_chunks, ...; others'
    entries are left alone."""
    w, h = cam[C_W], cam[C_H]
    if cam[C_TRANSPOSED] != 0.0:
        w, h = h, w
    x_lo, x_hi, y_lo, y_hi = -0.5 * w, 1.5 * w, -0.5 * h, 1.5 * h
    scratch = parts_scratch()
    pa = np.empty((MAX_PARTS, PART_COLS))
    pb = np.empty((MAX_PARTS, PART_COLS))
    c = np.empty(8)  # (one buffer: an allocation per part and time cost as much as the part's test)
    g = Q_GEO
    for o in range(ch, actors.shape[0], n_chunks):
        if not need[o]:
            continue
        for p in range(MAX_PARTS):
            part_rate[o, p] = 0.0
            part_y[o, p, 0], part_y[o, p, 1] = np.inf, -np.inf
        best = 0.0
        if int(actors[o, A_TYPE]) == TYPE_BAR:
            out[o] = abs(actors[o, R_VX])
            for p in range(MAX_PARTS):
                part_rate[o, p] = -1.0
                part_y[o, p, 0], part_y[o, p, 1] = -np.inf, np.inf
            continue
        if int(actors[o, A_TYPE]) != TYPE_PROP and not actors[o, P_H] > 0.0:
            # a zero-size walker shows no pixel (and has no stride to walk by)
            out[o] = 0.0
            continue
        actor_parts(actors[o], world, lut, bld, light, cam, rot_tab[0], pos_tab[0], times[0], pa, scratch)
        _part_lines(pa, part_y[o])
        for k in range(1, times.shape[0]):
            actor_parts(actors[o], world, lut, bld, light, cam, rot_tab[k], pos_tab[k], times[k], pb, scratch)
            _part_lines(pb, part_y[o])
            dt = times[k] - times[k - 1]
            for p in range(MAX_PARTS):
                if pa[p, Q_KIND] != pb[p, Q_KIND]:
                    part_rate[o, p] = -1.0
                if pa[p, Q_KIND] == PART_QUAD and pb[p, Q_KIND] == PART_QUAD:
                    v = _polygon_shift(pa, pb, p, x_lo, x_hi, y_lo, y_hi) / dt
                    best = max(best, v)
                    if part_rate[o, p] >= 0.0:
                        part_rate[o, p] = max(part_rate[o, p], v)
                    continue
                if pa[p, Q_KIND] != PART_CAPSULE or pb[p, Q_KIND] != PART_CAPSULE:
                    if pa[p, Q_KIND] != PART_NONE or pb[p, Q_KIND] != PART_NONE:
                        part_rate[o, p] = -1.0  # a shadow, or a change of kind: not measured here
                    continue
                off = True
                for q in (pa, pb):
                    r = q[p, g + 4]
                    if not (max(q[p, g], q[p, g + 2]) + r < x_lo or min(q[p, g], q[p, g + 2]) - r > x_hi
                            or q[p, Q_YMAX] < y_lo or q[p, Q_YMIN] > y_hi):
                        off = False
                if off:
                    continue
                for i in range(2):
                    c[4 * i] = _clamped(pa[p, g + 2 * i], x_lo, x_hi)
                    c[4 * i + 1] = _clamped(pa[p, g + 2 * i + 1], y_lo, y_hi)
                    c[4 * i + 2] = _clamped(pb[p, g + 2 * i], x_lo, x_hi)
                    c[4 * i + 3] = _clamped(pb[p, g + 2 * i + 1], y_lo, y_hi)
                da = math.hypot(c[2] - c[0], c[3] - c[1])
                db = math.hypot(c[6] - c[4], c[7] - c[5])
                d = max(da, db) + abs(pb[p, g + 4] - pa[p, g + 4])
                best = max(best, d / dt)
                if part_rate[o, p] >= 0.0:
                    part_rate[o, p] = max(part_rate[o, p], max(d, _texture_shift(pa, pb, p, c)) / dt)
            pa, pb = pb, pa
        out[o] = best


@njit(cache=True)
def _texture_shift(pa, pb, p, c):
    """Largest move of a point of capsule ``p``'s texture from ``pa`` to ``pb`` (``c``: its end points clamped as
    ``actor_speeds`` clamps them), which its end points' move does not bound when the axis turns.

    The texture is laid out from the first end a along the unit axis u, in pixels scaled by the radius
    (``rollcam.sim._texture.texture_at``). The point s along the axis and t across it moves by
    da + s du + t du', linear in s: over the part (-r <= s <= length + r, |t| <= r) at most the larger of its
    moves at the two ends of that range plus r |du|; a change of radius rescales the texture about a by
    (length + r) |dr| / r; and a head's face turns with its record. (A short axis, a head seen end on, turns fast
    for a small move of its ends.)"""
    g = Q_GEO
    axa, aya, axb, ayb = c[4] - c[0], c[5] - c[1], c[6] - c[2], c[7] - c[3]
    la, lb = math.hypot(axa, aya), math.hypot(axb, ayb)
    if la > 0.0 and lb > 0.0:
        dux, duy = axb / lb - axa / la, ayb / lb - aya / la
    elif la > 0.0 or lb > 0.0:
        dux, duy = 2.0, 0.0  # from the default direction to any: a bound on the turn's size
    else:
        dux, duy = 0.0, 0.0
    ra, rb = pa[p, g + 4], pb[p, g + 4]
    r = max(ra, rb)
    dax, day = c[2] - c[0], c[3] - c[1]
    far = max(la, lb) + r
    shift = max(math.hypot(dax - r * dux, day - r * duy), math.hypot(dax + far * dux, day + far * duy))
    shift += r * math.hypot(dux, duy) + far * abs(rb - ra) / max(min(ra, rb), 0.5)
    if pa[p, Q_FACE] >= -1.0 and pb[p, Q_FACE] >= -1.0:  # a head's face (-2: none)
        shift += r * math.hypot(pb[p, Q_FACE] - pa[p, Q_FACE], pb[p, Q_FACE + 1] - pa[p, Q_FACE + 1])
    return shift


@njit(cache=True)
def _part_lines(pt, ys):
    """Widen each shown part's line range ``ys[p]`` (lo, hi) to hold its ``Q_YMIN``..``Q_YMAX`` in ``pt``."""
    for p in range(MAX_PARTS):
        if pt[p, Q_KIND] != PART_NONE:
            ys[p, 0] = min(ys[p, 0], pt[p, Q_YMIN])
            ys[p, 1] = max(ys[p, 1], pt[p, Q_YMAX])


@njit(cache=True)
def _polygon_shift(pa, pb, p, x_lo, x_hi, y_lo, y_hi):
    """Largest move of a polygon part's vertices from ``pa`` to ``pb`` (0 when off the image at both), with the
    vertices clamped to the image's margin as ``actor_speeds`` clamps a capsule's end points."""
    g = Q_GEO
    off = True
    for q in (pa, pb):
        xs_lo, xs_hi = 1e300, -1e300
        for v in range(N_VERTS):
            xs_lo, xs_hi = min(xs_lo, q[p, g + 2 * v]), max(xs_hi, q[p, g + 2 * v])
        if not (xs_hi < x_lo or xs_lo > x_hi or q[p, Q_YMAX] < y_lo or q[p, Q_YMIN] > y_hi):
            off = False
    if off:
        return 0.0
    d = 0.0
    for v in range(N_VERTS):
        dx = _clamped(pb[p, g + 2 * v], x_lo, x_hi) - _clamped(pa[p, g + 2 * v], x_lo, x_hi)
        dy = _clamped(pb[p, g + 2 * v + 1], y_lo, y_hi) - _clamped(pa[p, g + 2 * v + 1], y_lo, y_hi)
        d = max(d, math.hypot(dx, dy))
    return d


@njit(cache=True)
def parts_scratch():
    """Scratch buffers ``actor_parts`` needs, allocated once per parallel work unit."""
    return (np.empty((MAX_PARTS, 6)), np.empty(MAX_PARTS), np.empty(MAX_PARTS, np.int64), np.empty(4), np.empty((5, 3)),
            np.empty((2 * N_VERTS, 3)))


@njit(cache=True)
def _bounds_chunk(ch, n_chunks, actors, world, cam, rot_tab, pos_tab, t_first, k_first, t_span, need, out):
    """Work unit ``ch`` of ``n_chunks`` of ``actor_bounds_all``: time groups ch, ch + n_chunks, ..."""
    n_obj, n_g = need.shape
    root = np.empty(4)
    pc = np.empty(3)
    uv = np.empty(2)
    for o in range(n_obj):
        for g in range(ch, n_g, n_chunks):
            if need[o, g]:
                k = k_first[g]
                actor_bounds(actors[o], world, cam, rot_tab[k], pos_tab[k], t_first[g], t_span[g], out[o, g],
                             root, pc, uv)


@njit(cache=True, nogil=True)
def actor_bounds_all(actors, world, cam, rot_tab, pos_tab, t_first, k_first, t_span, need, out):
    """out[o, g] = bounds of actor o over time group g (from t_first[g], lasting t_span[g]) where need[o, g]."""
    _bounds_chunk(0, 1, actors, world, cam, rot_tab, pos_tab, t_first, k_first, t_span, need, out)


@njit(cache=True, parallel=True, nogil=True)
def actor_bounds_par(actors, world, cam, rot_tab, pos_tab, t_first, k_first, t_span, need, out):
    """``actor_bounds_all`` over the numba threads (worth their start-up only for many bounds)."""
    for ch in prange(N_CHUNKS):
        _bounds_chunk(ch, N_CHUNKS, actors, world, cam, rot_tab, pos_tab, t_first, k_first, t_span, need, out)


@njit(cache=True)
def _parts_chunk(ch, n_chunks, actors, world, lut, bld, light, cam, rot_tab, pos_tab, times, slot_o, slot_k,
                 parts_tab):
    """Work unit ``ch`` of ``n_chunks`` of ``actor_parts_all``: slots ch, ch + n_chunks, ..."""
    scratch = parts_scratch()
    for s in range(ch, slot_o.shape[0], n_chunks):
        k = slot_k[s]
        actor_parts(actors[slot_o[s]], world, lut, bld, light, cam, rot_tab[k], pos_tab[k], times[k],
                    parts_tab[s], scratch)


@njit(cache=True, nogil=True)
def actor_parts_all(actors, world, lut, bld, light, cam, rot_tab, pos_tab, times, slot_o, slot_k, parts_tab):
    """parts_tab[s] = parts of actor slot_o[s] at times[slot_k[s]]."""
    _parts_chunk(0, 1, actors, world, lut, bld, light, cam, rot_tab, pos_tab, times, slot_o, slot_k, parts_tab)


@njit(cache=True, parallel=True, nogil=True)
def actor_parts_par(actors, world, lut, bld, light, cam, rot_tab, pos_tab, times, slot_o, slot_k, parts_tab):
    """``actor_parts_all`` over the numba threads (worth their start-up only for many slots)."""
    for ch in prange(N_CHUNKS):
        _parts_chunk(ch, N_CHUNKS, actors, world, lut, bld, light, cam, rot_tab, pos_tab, times, slot_o, slot_k,
                     parts_tab)


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
