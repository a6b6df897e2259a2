"""Numba kernels of the per-line renderer's lines: part spans on a line, span painting, the per-line render loop.

The static world (camera poses, background shading) is in ``world``, the actors' bounds and parts
in ``actors`` (over the walker model of ``body``); ``tables`` fills
the tables all of them read. Every function is pure: the same inputs give bit-identical outputs whichever path
(exact per-line, banded, brute-force reference) calls it, which is what lets the fast path equal the reference.

Render space: lines are rows of the render buffer. For column readout the camera is rendered transposed
(render row b = image column b), so one kernel serves all four readout directions.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .._jitcache import guard
from .actors import (
    MAX_PARTS,
    N_CHUNKS,
    N_VERTS,
    PART_COLS,
    PART_NONE,
    PART_QUAD,
    Q_AMB,
    Q_DEPTH,
    Q_DIR,
    Q_FACE,
    Q_GEO,
    Q_KIND,
    Q_LX,
    Q_LZ,
    Q_TEX,
    Q_TEXK,
    Q_TSEED,
    Q_YMAX,
    Q_YMIN,
    actor_parts,
    parts_scratch,
)
from .parts import PART_SHADOW
from .shader import encode_line_c
from .texture import NO_CELL, SH_FACE, SH_GEO, SH_TEX, SHADE_COLS, SHADOW_MARK, darken, texture_at, texture_span
from .world import C_MOVING, C_TRANSPOSED, background_line, background_span

# slots[o, k]: >= 0 row of the shared parts table; SLOT_NONE not needed; SLOT_LOCAL needed by a single line,
# so its parts are computed on that line (no table round trip through memory).
SLOT_NONE, SLOT_LOCAL = -1, -2
LUT_SIZE = 16384

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
    if parts[p, Q_KIND] == PART_SHADOW:  # |N (x - c)| <= 1 on the line: a quadratic in x
        n00, n01, n10, n11 = parts[p, g + 2], parts[p, g + 3], parts[p, g + 4], parts[p, g + 5]
        dv = yc - parts[p, g + 1]
        qa = n00 * n00 + n10 * n10
        qb = dv * (n00 * n01 + n10 * n11)
        qc = dv * dv * (n01 * n01 + n11 * n11) - 1.0
        disc = qb * qb - qa * qc
        if disc > 0.0 and qa > 0.0:
            r = math.sqrt(disc)
            lohi[0], lohi[1] = parts[p, g] + (-qb - r) / qa, parts[p, g] + (-qb + r) / qa
        return
    if parts[p, Q_KIND] == PART_QUAD:
        for e in range(N_VERTS):
            f = (e + 1) % N_VERTS
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
                  depth, idx_o, shade, span_l, span_r, pa, pb, lohi, want_gt):
    """Spans of every included actor on ``line`` (``obj_k[o]``: its time slot, -1 when not touching).

    Each span keeps its part's shading (``shade[m]``: Q_LX, Q_LZ, ambient RGB, direct RGB) so painting reads no
    part table: a view of one per span was reference-counted, which cost more than copying eight numbers.
    Fills the per-actor extent and area ground truth when ``want_gt`` (exposure integration needs none). Returns
    the number of spans.
    """
    yc = line + 0.5
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
        shadows = 0
        for p in range(MAX_PARTS):
            if pt[p, Q_KIND] == PART_NONE:
                continue
            if yc < pt[p, Q_YMIN] or yc > pt[p, Q_YMAX]:
                continue
            if pt[p, Q_KIND] == PART_SHADOW:
                shadows += 1  # after the body's spans: no part of the actor's extent or area
                continue
            part_span(pt, p, yc, lohi)
            if lohi[1] <= lohi[0] or lohi[1] <= 0.0 or lohi[0] >= w:
                continue
            depth[m], idx_o[m] = pt[p, Q_DEPTH], o
            shade[m, 0], shade[m, 1] = pt[p, Q_LX], pt[p, Q_LZ]
            for c in range(3):
                shade[m, 2 + c], shade[m, 5 + c] = pt[p, Q_AMB + c], pt[p, Q_DIR + c]
            shade[m, SH_TEX] = pt[p, Q_TEX]
            if pt[p, Q_TEX] > 0.0:
                for c in range(5):
                    shade[m, SH_GEO + c] = pt[p, Q_GEO + c]
                shade[m, SH_TEX + 1], shade[m, SH_TEX + 2] = pt[p, Q_TEXK], pt[p, Q_TSEED]
                for c in range(5):
                    shade[m, SH_FACE + c] = pt[p, Q_FACE + c]
            span_l[m], span_r[m] = lohi[0], lohi[1]
            m += 1
            olo, ohi = min(olo, lohi[0]), max(ohi, lohi[1])
        if m > m0 and want_gt:
            gt_tot[o, line] += _covered_pixels(span_l, span_r, m0, m, w, pa, pb)
        if ohi > olo and want_gt:
            gt_l[o, line] = max(olo, 0.0)
            gt_r[o, line] = min(ohi, float(w))
        for p in range(MAX_PARTS if shadows else 0):
            if pt[p, Q_KIND] != PART_SHADOW or yc < pt[p, Q_YMIN] or yc > pt[p, Q_YMAX]:
                continue
            part_span(pt, p, yc, lohi)
            if lohi[1] <= lohi[0] or lohi[1] <= 0.0 or lohi[0] >= w:
                continue
            depth[m], idx_o[m] = pt[p, Q_DEPTH], o
            for c in range(SH_TEX + 1):
                shade[m, c] = 0.0
            shade[m, 0] = SHADOW_MARK  # (a body part's Q_LX lies in [-1, 1])
            for c in range(3):
                shade[m, 2 + c] = pt[p, Q_AMB + c]
            shade[m, 5] = pt[p, Q_DIR]
            for c in range(5):
                shade[m, SH_GEO + c] = pt[p, Q_GEO + c]
            shade[m, 1] = pt[p, Q_GEO + 5]
            span_l[m], span_r[m] = lohi[0], lohi[1]
            m += 1
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
def _paint_spans(lin, line, m, gt_vis, depth, idx_o, shade, span_l, span_r, owner, ia, ib, n_runs, order, flip,
                 gt_only, want_gt):
    """Paint the collected spans over ``lin`` far to near (anti-aliased along the line); count visibility when
    ``want_gt``. ``gt_only`` counts visibility alone (which actor is nearest at each pixel centre needs no
    shading)."""
    w = lin.shape[0]
    # Insertion sort, far first; ties keep actor/part order so every path paints identically.
    for i in range(m):
        order[i] = i
    for i in range(1, m):
        j = i
        while j > 0 and depth[order[j - 1]] < depth[order[j]]:
            order[j - 1], order[j] = order[j], order[j - 1]
            j -= 1
    for ii in range(m):
        e = order[ii]
        o = idx_o[e]
        xl, xr = span_l[e], span_r[e]
        i0 = max(int(math.floor(xl)), 0)
        i1 = min(int(math.ceil(xr)), w)
        if shade[e, 0] == SHADOW_MARK:
            if not gt_only:
                darken(lin, line, shade, e, xl, xr, i0, i1)
            continue
        mid, half = 0.5 * (xl + xr), 0.5 * (xr - xl)
        lx, lz = shade[e, 0], shade[e, 1]
        textured = shade[e, SH_TEX] > 0.0
        ts = texture_span(shade, e, flip)
        cell = NO_CELL
        yc = line + 0.5
        for i in range(i0, i0 if gt_only else i1):
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
            f0, f1, f2, cell = texture_at(ts, i + 0.5, yc, cell) if textured else (1.0, 1.0, 1.0, cell)
            for c in range(3):
                v = (shade[e, 2 + c] + shade[e, 5 + c] * sh) * (f0 if c == 0 else f1 if c == 1 else f2)
                lin[i, c] = lin[i, c] * (1.0 - cov) + v * cov
        for i in range(max(int(math.ceil(xl - 0.5)), 0), min(int(math.ceil(xr - 0.5)), w) if want_gt else 0):
            owner[i] = o
    for j in range(n_runs if want_gt else 0):
        for i in range(ia[j], ib[j]):
            if owner[i] >= 0:
                gt_vis[owner[i], line] += 1
                owner[i] = -1  # leave the scratch clean for the next line


@njit(cache=True)
def encode_line(lin, gain, lut, out_u8):
    """Linear RGB pixels (n x 3, float32) to 8-bit BGR through the output curve ``lut`` (LUT_SIZE + 1 entries,
    uint8): scaled by ``gain``, clipped to [0, 1] (NaN to 0), nearest entry. The C shader library's vectorised
    loop; every array must be C-contiguous (the renderer's lines and tables are)."""
    encode_line_c(lin.ctypes.data, gain, lut.ctypes.data, lut.shape[0] - 1, out_u8.ctypes.data, lin.shape[0])


# ======================================================================================================
# a pass's set-up: which actor touches which entry, and where each actor's parts are computed
# ======================================================================================================


@njit(cache=True, nogil=True)
def touch_entries(bounds, group_of_k, k_line, objs, idx, centre, n_along, obj_k):
    """obj_k[o, e] = k_line[o, e] for each actor o in ``objs`` and entry e = idx[j] whose line centre
    ``centre[j]`` lies in the actor's bounds ``bounds[o, group_of_k[k]]`` (ymin, ymax, xmin, xmax), which reach
    the line's pixels; other entries are left alone. (In numpy this was a few (actors x entries) temporaries per
    render, a millisecond of a static-camera RS frame.)"""
    for a in range(objs.shape[0]):
        o = objs[a]
        for j in range(idx.shape[0]):
            e = idx[j]
            k = k_line[o, e]
            g = group_of_k[k]
            c = centre[j]
            if bounds[o, g, 0] <= c and c <= bounds[o, g, 1] and bounds[o, g, 2] < n_along and bounds[o, g, 3] > 0:
                obj_k[o, e] = k


@njit(cache=True, nogil=True)
def part_slots(obj_k, n_t, slots):
    """Fill ``slots`` (actors x times) from the time slots ``obj_k`` uses: SLOT_NONE unused, SLOT_LOCAL used by
    one entry, else the next row of the shared parts table (row-major order). Returns that table's (actor,
    time) per row."""
    n_obj, n_ent = obj_k.shape
    uses = np.zeros((n_obj, n_t), np.int64)
    for o in range(n_obj):
        for e in range(n_ent):
            k = obj_k[o, e]
            if k >= 0:
                uses[o, k] += 1
    n = 0
    for o in range(n_obj):
        for k in range(n_t):
            u = uses[o, k]
            slots[o, k] = SLOT_NONE if u == 0 else (SLOT_LOCAL if u == 1 else n)
            if u > 1:
                n += 1
    s_o = np.empty(n, np.int64)
    s_k = np.empty(n, np.int64)
    for o in range(n_obj):
        for k in range(n_t):
            if slots[o, k] >= 0:
                s_o[slots[o, k]], s_k[slots[o, k]] = o, k
    return s_o, s_k


# ======================================================================================================
# the per-line render loop
# ======================================================================================================


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


@njit(cache=True)
def _add_over(dst, lin, base, ia, ib, n_runs, first):
    """Accumulate what one painted line adds to its bare background ``base`` (both (w, 3)) inside the runs into
    ``dst`` (zeroed on the line's first hit): a moving camera's actors, whose background is integrated apart."""
    if first:
        dst[:, :] = 0.0
    for r in range(n_runs):
        for i in range(ia[r], ib[r]):
            for c in range(3):
                dst[i, c] += lin[i, c] - base[i, c]


@njit(cache=True, nogil=True)
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

    A moving camera without ``full_lines`` (and not ``gt_only``) shades the background at each entry's own pose
    under the actor spans only; accumulating, it then adds just what the actors change there (``_add_over``).

    An empty ``out_u8`` skips the sRGB encoding (linear-only renders). A non-empty ``seed_lin`` (the cached
    linear composite) is copied into each painted line of ``out_lin`` first, so ``out_lin`` may be a scratch
    buffer whose other lines are never touched. A non-empty ``acc_hits`` (int64 per line) turns ``out_lin`` into
    an accumulator of painted lines (see ``_add_line``), and each painted line's count goes up; it writes no ground
    truth (the per-entry extents, areas and visibility an integration would throw away). In both modes
    a line on which no actor has a span equals the composite and is left alone; ``line_hit`` (bool per line,
    when non-empty) records which lines were written.
    """
    _render_chunk(0, 1, world, lut_b, bld, light, cam, rot_tab, pos_tab, actors, times, line_k, obj_line_k,
                  slots, parts_tab, include, lines, e_start, ents, w, bg_lin, out_u8, out_lin, gain, lut, gt_l, gt_r,
                  gt_tot, gt_vis, gt_only, full_lines, seed_lin, acc_hits, line_hit)


@njit(cache=True, parallel=True, nogil=True)
def render_lines_par(world, lut_b, bld, light, cam, rot_tab, pos_tab, actors, times, line_k, obj_line_k, slots,
                     parts_tab, include, lines, e_start, ents, w, bg_lin, out_u8, out_lin, gain, lut, gt_l, gt_r,
                     gt_tot, gt_vis, gt_only, full_lines, seed_lin, acc_hits, line_hit):
    """``render_lines_kernel`` over the numba threads, N_CHUNKS interleaved sets of lines (worth the threads'
    start-up only for many pixels: a busy machine may take milliseconds to give a parked thread a core)."""
    for ch in prange(N_CHUNKS):
        _render_chunk(ch, N_CHUNKS, world, lut_b, bld, light, cam, rot_tab, pos_tab, actors, times, line_k, obj_line_k,
                      slots, parts_tab, include, lines, e_start, ents, w, bg_lin, out_u8, out_lin, gain, lut, gt_l,
                      gt_r, gt_tot, gt_vis, gt_only, full_lines, seed_lin, acc_hits, line_hit)


@njit(cache=True)
def _render_chunk(ch, n_chunks, world, lut_b, bld, light, cam, rot_tab, pos_tab, actors, times, line_k, obj_line_k,
                  slots, parts_tab, include, lines, e_start, ents, w, bg_lin, out_u8, out_lin, gain, lut, gt_l, gt_r,
                  gt_tot, gt_vis, gt_only, full_lines, seed_lin, acc_hits, line_hit):
    """Work unit ``ch`` of ``n_chunks`` of ``render_lines_kernel``: lines ch, ch + n_chunks, ..."""
    n_obj = actors.shape[0]
    moving_cam = cam[C_MOVING] != 0.0
    want_lin = out_lin.shape[0] > 0
    want_u8 = out_u8.shape[0] > 0
    seed = seed_lin.shape[0] > 0 and want_lin and not full_lines
    accumulate = acc_hits.shape[0] > 0
    spans_moving = moving_cam and not full_lines and not gt_only  # actors over the background at their pose
    want_gt = not accumulate  # an accumulator's truth is scratch: nobody reads it
    cap = max(n_obj * MAX_PARTS, 1)
    n = lines.shape[0]
    depth = np.empty(cap)
    idx_o = np.empty(cap, np.int64)
    shade = np.empty((cap, SHADE_COLS))
    flip = -1.0 if cam[C_TRANSPOSED] != 0.0 else 1.0
    order = np.empty(cap, np.int64)  # scratch of every line: an allocation per line costs as much as its work
    lohi = np.empty(2)
    span_l = np.empty(cap)
    span_r = np.empty(cap)
    pa = np.empty(cap, np.int64)
    pb = np.empty(cap, np.int64)
    owner = np.full(w, -1, np.int64)
    ia = np.empty(cap + 1, np.int64)
    ib = np.empty(cap + 1, np.int64)
    lin = np.empty((w, 3), np.float32)
    base = np.empty((w if spans_moving else 0, 3), np.float32)
    no_surface = np.empty(0, np.int8)
    local = np.empty((max(n_obj, 1), MAX_PARTS, PART_COLS))
    scratch = parts_scratch()
    for j in range(ch, n, n_chunks):
        line = lines[j]
        for q in range(e_start[j], e_start[j + 1]):
            e = ents[q]
            ok = obj_line_k[:, e]
            for o in range(n_obj):
                if want_gt:
                    gt_l[o, line], gt_r[o, line], gt_tot[o, line], gt_vis[o, line] = np.nan, np.nan, 0, 0
                if include[o] and ok[o] >= 0 and slots[o, ok[o]] == SLOT_LOCAL:
                    k = ok[o]
                    actor_parts(actors[o], world, lut_b, bld, light, cam, rot_tab[k], pos_tab[k], times[k],
                                local[o], scratch)
            m = _collect_line(line, w, actors, ok, slots, parts_tab, local, include, gt_l, gt_r, gt_tot,
                              depth, idx_o, shade, span_l, span_r, pa, pb, lohi, want_gt)
            if full_lines and not gt_only:
                if moving_cam:
                    k = line_k[e]
                    background_line(world, lut_b, bld, light, cam, rot_tab[k], pos_tab[k], line, lin)
                else:
                    lin[:, :] = bg_lin[line]
                ia[0], ib[0], n_runs = 0, w, 1
            else:
                n_runs = _span_runs(span_l, span_r, m, w, ia, ib)
                if spans_moving:
                    k = line_k[e]
                    for r in range(n_runs):
                        background_span(world, lut_b, bld, light, cam, rot_tab[k], pos_tab[k], float(line), ia[r],
                                        ib[r], base[ia[r]:ib[r]], no_surface)
                        lin[ia[r]:ib[r]] = base[ia[r]:ib[r]]
                elif not gt_only:
                    for r in range(n_runs):
                        lin[ia[r]:ib[r]] = bg_lin[line, ia[r]:ib[r]]
            if m > 0:
                _paint_spans(lin, line, m, gt_vis, depth, idx_o, shade, span_l, span_r, owner, ia, ib, n_runs, order,
                             flip, gt_only, want_gt)
            if (seed or spans_moving) and m == 0:
                continue  # no actor pixel on this line: it is the composite (or bare background), nothing to write
            if line_hit.shape[0] > 0:
                line_hit[line] = True
            if accumulate and spans_moving:
                _add_over(out_lin[line], lin, base, ia, ib, n_runs, acc_hits[line] == 0)
                acc_hits[line] += 1
            elif accumulate and not gt_only:
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


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
