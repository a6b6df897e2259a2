"""Numba kernels of the per-line renderer: actor bounds and parts, span painting, the per-line render loop.

The static world (camera poses, background shading) is in ``rollcam.sim._world``, the walker model in
``rollcam.sim._body``; ``rollcam.sim.compile`` fills the tables all of them read.
Every function is pure: the same inputs give bit-identical outputs whichever path (exact per-line, banded,
brute-force reference) calls it, which is what lets the fast path equal the reference.

Render space: lines are rows of the render buffer. For column readout the camera is rendered transposed
(render row b = image column b), so one kernel serves all four readout directions.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


def _drop_stale_cache() -> None:
    """Remove this module's numba cache when a module it compiles in (``_body``, ``_world``) is newer.

    Numba keys a cached function on its own source file only, but these kernels compile the walker model and
    the world shading into themselves; without this, an edit there would keep running from stale cache.
    """
    from pathlib import Path

    here = Path(__file__).resolve().parent
    try:
        newest = max((here / name).stat().st_mtime for name in ("_body.py", "_world.py"))
        for f in (here / "__pycache__").glob("_kernels.*.nb[ci]"):
            if f.stat().st_mtime < newest:
                f.unlink(missing_ok=True)
    except OSError:
        pass  # read-only install: nothing is edited there, so nothing can be stale


_drop_stale_cache()

from ._body import (  # noqa: E402  (actor table layout lives with the body model)
    A_TYPE,
    P_BUILD,
    P_H,
    P_SKIN,
    P_SPEED,
    R_PERIOD,
    R_RGB,
    R_VX,
    R_WIDTH,
    R_X0,
    TYPE_BAR,
    pedestrian_root,
    pedestrian_skeleton,
)
from ._world import (  # noqa: E402
    C_CX,
    C_CY,
    C_FX,
    C_FY,
    C_H,
    C_MOVING,
    C_TRANSPOSED,
    C_W,
    KIND_STREET,
    L_AMB,
    L_SUN,
    L_SUN_RGB,
    W_KIND,
    W_YHALF,
    _sun_blocked,
    background_line,
    to_camera,
)

# ---- part table (one actor at one time) ---------------------------------------------------------------------
Q_KIND, Q_DEPTH, Q_AMB, Q_DIR, Q_LX, Q_LZ, Q_GEO, Q_YMIN, Q_YMAX = 0, 1, 2, 5, 8, 9, 10, 18, 19
PART_COLS = 20
MAX_PARTS = 16
PART_CAPSULE, PART_QUAD, PART_NONE = 0, 1, -1
# slots[o, k]: >= 0 row of the shared parts table; SLOT_NONE not needed; SLOT_LOCAL needed by a single line,
# so its parts are computed on that line (no table round trip through memory).
SLOT_NONE, SLOT_LOCAL = -1, -2
NEAR_M = 0.05
BODY_LATERAL, BODY_FORWARD, BODY_TOP = 0.25, 0.40, 1.02  # walker bounds, fractions of height (see actor_bounds)
PART_RADIUS_MAX = 0.1  # walker part radii, fraction of height x build (the largest in _body is 0.08)
LUT_SIZE = 16384

# ======================================================================================================
# actors
# ======================================================================================================


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
    pedestrian_root(act, t, root)
    root[1] += _lane_shift(world, pos, root[1])
    h = act[P_H]
    # Body reach from the root, with margin: arms and hips at most 0.18 h x build sideways, feet and hands
    # at most 0.32 h forward or back, head top at 1.007 h (tests/test_render.py checks the containment).
    lat = BODY_LATERAL * h * max(act[P_BUILD], 1.0)
    e = BODY_FORWARD * h
    n_behind = 0
    ey = e + abs(act[P_SPEED]) * dt  # walkers move along Y only, at most speed * dt either way
    corners = np.empty((8, 3))
    for i in range(8):
        x = root[0] + (lat if i & 1 else -lat)
        y = root[1] + (ey if i & 2 else -ey)
        z = BODY_TOP * h if i & 4 else -0.02 * h  # feet dip a little below the ground plane
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
        pad = cam[C_FX] * PART_RADIUS_MAX * h * max(act[P_BUILD], 1.0) / NEAR_M
        out[0], out[1], out[2], out[3] = out[0] - pad, out[1] + pad, out[2] - pad, out[3] + pad


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
    parts[p, Q_YMIN] = min(min(y0, y1), min(y2, y3))
    parts[p, Q_YMAX] = max(max(y0, y1), max(y2, y3))


@njit(cache=True)
def actor_parts(act, world, lut, bld, light, cam, rot, pos, t, parts, scratch):
    """Fill ``parts`` (MAX_PARTS x PART_COLS) with the render-space primitives of an actor at time ``t``."""
    seg, rad, col_idx, root, joints, a, b, ua, ub = scratch
    for p in range(MAX_PARTS):
        parts[p, Q_KIND] = PART_NONE
    typ = int(act[A_TYPE])
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
    lit = 0.0 if _sun_blocked(world, lut, bld, root[0], root[1], 0.7 * act[P_H], light, -1) else 1.0
    # Sun direction in camera frame, reduced to the image-plane x / viewing-axis z for cylinder shading.
    sx = rot[0, 0] * light[L_SUN] + rot[0, 1] * light[L_SUN + 1] + rot[0, 2] * light[L_SUN + 2]
    sz = -(rot[2, 0] * light[L_SUN] + rot[2, 1] * light[L_SUN + 1] + rot[2, 2] * light[L_SUN + 2])
    sy_up = light[L_SUN + 2]
    nrm = math.sqrt(sx * sx + sz * sz) + 1e-12
    horiz = math.sqrt(max(0.0, 1.0 - sy_up * sy_up))
    lxv, lzv = sx / nrm * horiz, sz / nrm * horiz
    for p in range(n):
        to_camera(rot, pos, seg[p, 0], seg[p, 1], seg[p, 2], a)
        to_camera(rot, pos, seg[p, 3], seg[p, 4], seg[p, 5], b)
        if a[2] < NEAR_M and b[2] < NEAR_M:
            continue
        # Clip the segment at the near plane so parts crossing the camera plane stay finite.
        if a[2] < NEAR_M:
            f = (NEAR_M - a[2]) / (b[2] - a[2])
            for c in range(3):
                a[c] = a[c] + f * (b[c] - a[c])
        elif b[2] < NEAR_M:
            f = (NEAR_M - b[2]) / (a[2] - b[2])
            for c in range(3):
                b[c] = b[c] + f * (a[c] - b[c])
        zm = 0.5 * (a[2] + b[2])
        _project(cam, a[0], a[1], a[2], ua)
        _project(cam, b[0], b[1], b[2], ub)
        r_px = cam[C_FX] * rad[p] / zm
        ci = col_idx[p]
        base = P_SKIN + 3 * ci
        parts[p, Q_KIND] = PART_CAPSULE
        parts[p, Q_DEPTH] = zm
        for c in range(3):
            alb = act[base + c]
            parts[p, Q_AMB + c] = alb * light[L_AMB + c]
            parts[p, Q_DIR + c] = alb * light[L_SUN_RGB + c] * lit
        parts[p, Q_LX], parts[p, Q_LZ] = lxv, lzv
        if cam[C_TRANSPOSED] != 0.0:
            parts[p, Q_LX] = 0.0  # a transposed line runs along the image's y axis
        g = Q_GEO
        parts[p, g], parts[p, g + 1], parts[p, g + 2], parts[p, g + 3] = ua[0], ua[1], ub[0], ub[1]
        parts[p, g + 4] = r_px
        parts[p, Q_YMIN] = min(ua[1], ub[1]) - r_px
        parts[p, Q_YMAX] = max(ua[1], ub[1]) + r_px


@njit(cache=True, inline="always")
def _clamped(v, lo, hi):
    return min(max(v, lo), hi)


@njit(cache=True)
def actor_speeds(actors, world, lut, bld, light, cam, rot_tab, pos_tab, times, out):
    """out[o] = fastest render-space displacement rate (px/s) of any part end point of actor o.

    Parts wholly off the image (beyond half its size) at both times cannot move a pixel and are skipped;
    end points are clamped to that margin, so a part clipped at the camera's near plane (whose clipped end
    point races across image space far outside the frame) counts only its motion near the image.
    """
    w, h = cam[C_W], cam[C_H]
    if cam[C_TRANSPOSED] != 0.0:
        w, h = h, w
    x_lo, x_hi, y_lo, y_hi = -0.5 * w, 1.5 * w, -0.5 * h, 1.5 * h
    scratch = parts_scratch()
    pa = np.empty((MAX_PARTS, PART_COLS))
    pb = np.empty((MAX_PARTS, PART_COLS))
    g = Q_GEO
    for o in range(actors.shape[0]):
        best = 0.0
        if int(actors[o, A_TYPE]) == TYPE_BAR:
            out[o] = abs(actors[o, R_VX])
            continue
        if not actors[o, P_H] > 0.0:  # a zero-size walker shows no pixel (and has no stride to walk by)
            out[o] = 0.0
            continue
        actor_parts(actors[o], world, lut, bld, light, cam, rot_tab[0], pos_tab[0], times[0], pa, scratch)
        for k in range(1, times.shape[0]):
            actor_parts(actors[o], world, lut, bld, light, cam, rot_tab[k], pos_tab[k], times[k], pb, scratch)
            dt = times[k] - times[k - 1]
            for p in range(MAX_PARTS):
                if pa[p, Q_KIND] != PART_CAPSULE or pb[p, Q_KIND] != PART_CAPSULE:
                    continue
                off = True
                for q in (pa, pb):
                    r = q[p, g + 4]
                    if not (max(q[p, g], q[p, g + 2]) + r < x_lo or min(q[p, g], q[p, g + 2]) - r > x_hi
                            or q[p, Q_YMAX] < y_lo or q[p, Q_YMIN] > y_hi):
                        off = False
                if off:
                    continue
                c = np.empty(8)
                for i in range(2):
                    c[4 * i] = _clamped(pa[p, g + 2 * i], x_lo, x_hi)
                    c[4 * i + 1] = _clamped(pa[p, g + 2 * i + 1], y_lo, y_hi)
                    c[4 * i + 2] = _clamped(pb[p, g + 2 * i], x_lo, x_hi)
                    c[4 * i + 3] = _clamped(pb[p, g + 2 * i + 1], y_lo, y_hi)
                da = math.hypot(c[2] - c[0], c[3] - c[1])
                db = math.hypot(c[6] - c[4], c[7] - c[5])
                d = max(da, db) + abs(pb[p, g + 4] - pa[p, g + 4])
                best = max(best, d / dt)
            pa, pb = pb, pa
        out[o] = best


# ======================================================================================================
# spans and line painting
# ======================================================================================================


@njit(cache=True, inline="always")
def _edge(px, py, qx, qy, yc, lohi):
    if (py - yc) * (qy - yc) <= 0.0:
        if py != qy:
            x = px + (yc - py) * (qx - px) / (qy - py)
            lohi[0], lohi[1] = min(lohi[0], x), max(lohi[1], x)
        else:
            lohi[0], lohi[1] = min(lohi[0], min(px, qx)), max(lohi[1], max(px, qx))


@njit(cache=True, inline="always")
def part_span(parts, p, yc, lohi):
    """Continuous x-interval of part ``p`` on the line through ``yc``; lohi = (inf, -inf) when empty."""
    lohi[0], lohi[1] = 1e30, -1e30
    g = Q_GEO
    if parts[p, Q_KIND] == PART_QUAD:
        for e in range(4):
            f = (e + 1) % 4
            _edge(parts[p, g + 2 * e], parts[p, g + 2 * e + 1], parts[p, g + 2 * f], parts[p, g + 2 * f + 1],
                  yc, lohi)
        return
    ax, ay, bx, by, r = parts[p, g], parts[p, g + 1], parts[p, g + 2], parts[p, g + 3], parts[p, g + 4]
    for px, py in ((ax, ay), (bx, by)):
        dy = yc - py
        if abs(dy) <= r:
            d = math.sqrt(r * r - dy * dy)
            lohi[0], lohi[1] = min(lohi[0], px - d), max(lohi[1], px + d)
    ln = math.hypot(bx - ax, by - ay)
    if ln > 0.0:
        nx, ny = -(by - ay) / ln * r, (bx - ax) / ln * r
        _edge(ax + nx, ay + ny, bx + nx, by + ny, yc, lohi)
        _edge(bx + nx, by + ny, bx - nx, by - ny, yc, lohi)
        _edge(bx - nx, by - ny, ax - nx, ay - ny, yc, lohi)
        _edge(ax - nx, ay - ny, ax + nx, ay + ny, yc, lohi)


@njit(cache=True)
def _covered_pixels(span_l, span_r, m0, m, w, pa, pb):
    """Pixels whose centre lies in the union of spans m0..m-1 (one actor's parts on one line)."""
    n = 0
    for e in range(m0, m):
        a = max(int(math.ceil(span_l[e] - 0.5)), 0)
        b = min(int(math.ceil(span_r[e] - 0.5)), w)
        if b <= a:
            continue
        j = n
        while j > 0 and pa[j - 1] > a:  # insertion sort by start
            pa[j], pb[j] = pa[j - 1], pb[j - 1]
            j -= 1
        pa[j], pb[j] = a, b
        n += 1
    total = 0
    cur_a, cur_b = 0, 0
    for j in range(n):
        if j == 0 or pa[j] > cur_b:
            total += cur_b - cur_a
            cur_a, cur_b = pa[j], pb[j]
        elif pb[j] > cur_b:
            cur_b = pb[j]
    return total + cur_b - cur_a


@njit(cache=True)
def _collect_line(line, w, actors, obj_k, slots, parts_tab, local, include, gt_l, gt_r, gt_tot,
                  depth, idx_o, idx_p, span_l, span_r, pa, pb):
    """Spans of every included actor on ``line`` (``obj_k[o]``: its time slot, -1 when not touching).

    Fills the per-actor extent and area ground truth. Returns the number of spans.
    """
    yc = line + 0.5
    lohi = np.empty(2)
    m = 0
    for o in range(actors.shape[0]):
        if not include[o] or obj_k[o] < 0:
            continue
        s = slots[o, obj_k[o]]
        if s == SLOT_NONE:
            continue
        pt = parts_tab[s] if s >= 0 else local[o]
        olo, ohi = 1e30, -1e30
        m0 = m
        for p in range(MAX_PARTS):
            if pt[p, Q_KIND] == PART_NONE:
                continue
            if yc < pt[p, Q_YMIN] or yc > pt[p, Q_YMAX]:
                continue
            part_span(pt, p, yc, lohi)
            if lohi[1] <= lohi[0] or lohi[1] <= 0.0 or lohi[0] >= w:
                continue
            depth[m], idx_o[m], idx_p[m] = pt[p, Q_DEPTH], o, p
            span_l[m], span_r[m] = lohi[0], lohi[1]
            m += 1
            olo, ohi = min(olo, lohi[0]), max(ohi, lohi[1])
        if m > m0:
            gt_tot[o, line] += _covered_pixels(span_l, span_r, m0, m, w, pa, pb)
        if ohi > olo:
            gt_l[o, line] = max(olo, 0.0)
            gt_r[o, line] = min(ohi, float(w))
    return m


@njit(cache=True)
def _span_runs(span_l, span_r, m, w, ia, ib):
    """Merge the pixel ranges the spans touch into sorted disjoint runs [ia[j], ib[j]); returns the count."""
    n = 0
    for e in range(m):
        a = max(int(math.floor(span_l[e])), 0)
        b = min(int(math.ceil(span_r[e])), w)
        if b <= a:
            continue
        j = n
        while j > 0 and ia[j - 1] > a:
            ia[j], ib[j] = ia[j - 1], ib[j - 1]
            j -= 1
        ia[j], ib[j] = a, b
        n += 1
    k = 0
    for j in range(n):
        if k > 0 and ia[j] <= ib[k - 1]:
            ib[k - 1] = max(ib[k - 1], ib[j])
        else:
            ia[k], ib[k] = ia[j], ib[j]
            k += 1
    return k


@njit(cache=True)
def _paint_spans(lin, line, m, obj_k, slots, parts_tab, local, gt_vis, depth, idx_o, idx_p, span_l, span_r, owner,
                 ia, ib, n_runs):
    """Paint the collected spans over ``lin`` far to near (anti-aliased along the line); count visibility."""
    w = lin.shape[0]
    # Insertion sort, far first; ties keep actor/part order so every path paints identically.
    order = np.arange(m)
    for i in range(1, m):
        j = i
        while j > 0 and depth[order[j - 1]] < depth[order[j]]:
            order[j - 1], order[j] = order[j], order[j - 1]
            j -= 1
    for ii in range(m):
        e = order[ii]
        o, p = idx_o[e], idx_p[e]
        s = slots[o, obj_k[o]]
        pt = parts_tab[s] if s >= 0 else local[o]
        xl, xr = span_l[e], span_r[e]
        i0 = max(int(math.floor(xl)), 0)
        i1 = min(int(math.ceil(xr)), w)
        mid, half = 0.5 * (xl + xr), 0.5 * (xr - xl)
        lx, lz = pt[p, Q_LX], pt[p, Q_LZ]
        for i in range(i0, i1):
            cov = min(xr, i + 1.0) - max(xl, float(i))
            if cov <= 0.0:
                continue
            u = (i + 0.5 - mid) / half
            if u > 1.0:
                u = 1.0
            elif u < -1.0:
                u = -1.0
            sh = lx * u + lz * math.sqrt(1.0 - u * u)
            if sh < 0.0:
                sh = 0.0
            for c in range(3):
                v = pt[p, Q_AMB + c] + pt[p, Q_DIR + c] * sh
                lin[i, c] = lin[i, c] * (1.0 - cov) + v * cov
        for i in range(max(int(math.ceil(xl - 0.5)), 0), min(int(math.ceil(xr - 0.5)), w)):
            owner[i] = o
    for j in range(n_runs):
        for i in range(ia[j], ib[j]):
            if owner[i] >= 0:
                gt_vis[owner[i], line] += 1
                owner[i] = -1  # leave the scratch clean for the next line


@njit(cache=True)
def encode_line(lin, gain, lut, out_u8):
    """Linear RGB line to 8-bit BGR through the output curve ``lut`` (LUT_SIZE + 1 entries)."""
    for i in range(lin.shape[0]):
        for c in range(3):
            v = lin[i, c] * gain
            if v < 0.0:
                v = 0.0
            elif v > 1.0:
                v = 1.0
            out_u8[i, 2 - c] = lut[int(v * LUT_SIZE + 0.5)]


@njit(cache=True)
def parts_scratch():
    """Scratch buffers ``actor_parts`` needs, allocated once per parallel work unit."""
    return (np.empty((MAX_PARTS, 6)), np.empty(MAX_PARTS), np.empty(MAX_PARTS, np.int64), np.empty(4),
            np.empty((5, 3)), np.empty(3), np.empty(3), np.empty(2), np.empty(2))


N_CHUNKS = 16  # parallel work units; scratch buffers are allocated once per unit, not per item


@njit(cache=True, parallel=True)
def actor_bounds_all(actors, world, cam, rot_tab, pos_tab, t_first, k_first, t_span, need, out):
    """out[o, g] = bounds of actor o over time group g (from t_first[g], lasting t_span[g]) where need[o, g]."""
    n_obj, n_g = need.shape
    for ch in prange(N_CHUNKS):
        root = np.empty(4)
        pc = np.empty(3)
        uv = np.empty(2)
        for o in range(n_obj):
            for g in range(ch, n_g, N_CHUNKS):
                if need[o, g]:
                    k = k_first[g]
                    actor_bounds(actors[o], world, cam, rot_tab[k], pos_tab[k], t_first[g], t_span[g], out[o, g],
                                 root, pc, uv)


@njit(cache=True, parallel=True)
def actor_parts_all(actors, world, lut, bld, light, cam, rot_tab, pos_tab, times, slot_o, slot_k, parts_tab):
    """parts_tab[s] = parts of actor slot_o[s] at times[slot_k[s]]."""
    n = slot_o.shape[0]
    for ch in prange(N_CHUNKS):
        scratch = parts_scratch()
        for s in range(ch, n, N_CHUNKS):
            k = slot_k[s]
            actor_parts(actors[slot_o[s]], world, lut, bld, light, cam, rot_tab[k], pos_tab[k], times[k],
                        parts_tab[s], scratch)


@njit(cache=True)
def _add_line(dst, lin, seed_lin, line, seed, ia, ib, n_runs, first):
    """Accumulate one painted line into ``dst`` (that line of the accumulator).

    Over a composite (``seed``) only what differs from it is kept: dst gets lin - composite inside the runs
    (pixels outside them equal the composite), zeroed on the line's first hit. Without one (a moving camera,
    whole lines painted) dst is the plain sum of the painted lines.
    """
    if seed:
        if first:
            dst[:, :] = 0.0
        for r in range(n_runs):
            for i in range(ia[r], ib[r]):
                for c in range(3):
                    dst[i, c] += lin[i, c] - seed_lin[line, i, c]
        return
    for r in range(n_runs):
        for i in range(ia[r], ib[r]):
            for c in range(3):
                dst[i, c] = lin[i, c] if first else dst[i, c] + lin[i, c]


@njit(cache=True, parallel=True)
def render_lines_kernel(world, lut_b, bld, light, cam, rot_tab, pos_tab, actors, times, line_k, obj_line_k, slots,
                        parts_tab, include, lines, e_start, ents, w, bg_lin, out_u8, out_lin, gain, lut, gt_l, gt_r,
                        gt_tot, gt_vis, gt_only, full_lines, seed_lin, acc_hits, line_hit):
    """Paint the given ``lines``; every other line already holds the cached composite (copied by the caller).

    Line ``lines[j]`` is painted once per entry ``ents[e_start[j]:e_start[j + 1]]`` (one entry per line, the
    line itself, for a frame; one per sample for exposure integration, which accumulates them), in order, by
    one worker. ``obj_line_k[o, e]`` is actor o's time slot on entry e (-1 when not touching) and
    ``line_k[e]`` the entry's own time slot; ground truth is indexed by line. With ``full_lines``
    (moving camera, or building the composite) each line is rendered whole, from the background rendered
    at the line's own pose when the camera moves, else from the cached ``bg_lin``; otherwise only the pixel
    runs under actor spans are redone over ``bg_lin``. Ground truth of painted lines is recomputed.

    An empty ``out_u8`` skips the sRGB encoding (linear-only renders). A non-empty ``seed_lin`` (the cached
    linear composite) is copied into each painted line of ``out_lin`` first, so ``out_lin`` may be a scratch
    buffer whose other lines are never touched. A non-empty ``acc_hits`` (int64 per line) turns ``out_lin`` into
    an accumulator of painted lines (see ``_add_line``), and each painted line's count goes up. In both modes
    a line on which no actor has a span equals the composite and is left alone; ``line_hit`` (bool per line,
    when non-empty) records which lines were written.
    """
    n_obj = actors.shape[0]
    moving_cam = cam[C_MOVING] != 0.0
    want_lin = out_lin.shape[0] > 0
    want_u8 = out_u8.shape[0] > 0
    seed = seed_lin.shape[0] > 0 and want_lin and not full_lines
    accumulate = acc_hits.shape[0] > 0
    cap = max(n_obj * MAX_PARTS, 1)
    n = lines.shape[0]
    for ch in prange(N_CHUNKS):
        depth = np.empty(cap)
        idx_o = np.empty(cap, np.int64)
        idx_p = np.empty(cap, np.int64)
        span_l = np.empty(cap)
        span_r = np.empty(cap)
        pa = np.empty(cap, np.int64)
        pb = np.empty(cap, np.int64)
        owner = np.full(w, -1, np.int64)
        ia = np.empty(cap + 1, np.int64)
        ib = np.empty(cap + 1, np.int64)
        lin = np.empty((w, 3), np.float32)
        local = np.empty((max(n_obj, 1), MAX_PARTS, PART_COLS))
        scratch = parts_scratch()
        for j in range(ch, n, N_CHUNKS):
            line = lines[j]
            for q in range(e_start[j], e_start[j + 1]):
                e = ents[q]
                ok = obj_line_k[:, e]
                for o in range(n_obj):
                    gt_l[o, line], gt_r[o, line], gt_tot[o, line], gt_vis[o, line] = np.nan, np.nan, 0, 0
                    if include[o] and ok[o] >= 0 and slots[o, ok[o]] == SLOT_LOCAL:
                        k = ok[o]
                        actor_parts(actors[o], world, lut_b, bld, light, cam, rot_tab[k], pos_tab[k], times[k],
                                    local[o], scratch)
                m = _collect_line(line, w, actors, ok, slots, parts_tab, local, include, gt_l, gt_r, gt_tot,
                                  depth, idx_o, idx_p, span_l, span_r, pa, pb)
                if full_lines and not gt_only:
                    if moving_cam:
                        k = line_k[e]
                        background_line(world, lut_b, bld, light, cam, rot_tab[k], pos_tab[k], line, lin)
                    else:
                        lin[:, :] = bg_lin[line]
                    ia[0], ib[0], n_runs = 0, w, 1
                else:
                    n_runs = _span_runs(span_l, span_r, m, w, ia, ib)
                    if not gt_only:
                        for r in range(n_runs):
                            lin[ia[r]:ib[r]] = bg_lin[line, ia[r]:ib[r]]
                if m > 0:
                    _paint_spans(lin, line, m, ok, slots, parts_tab, local, gt_vis, depth, idx_o, idx_p, span_l,
                                 span_r, owner, ia, ib, n_runs)
                if seed and m == 0:
                    continue  # no actor pixel on this line: it is the composite, nothing to write
                if line_hit.shape[0] > 0:
                    line_hit[line] = True
                if accumulate and not gt_only:
                    _add_line(out_lin[line], lin, seed_lin, line, seed, ia, ib, n_runs, acc_hits[line] == 0)
                    acc_hits[line] += 1
                elif not gt_only:
                    if seed:
                        out_lin[line, :, :] = seed_lin[line]
                    for r in range(n_runs):
                        x0, x1 = ia[r], ib[r]
                        if want_lin:
                            out_lin[line, x0:x1, :] = lin[x0:x1]
                        if want_u8:
                            encode_line(lin[x0:x1], gain, lut, out_u8[line, x0:x1])
