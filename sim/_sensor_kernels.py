"""The numba kernels of the EMVA sensor model (``rollcam.sim.noise``): fixed patterns, mosaic, exposure.

A frame is made row by row in three straight (vectorisable) loops. ``_prep_row`` turns a row's filtered
radiance into each pixel's mean in DN, ``(mu + DSNU) K + black``, and the spread of its shot plus read noise
in DN, ``sqrt(mu + read**2) K``, as float32, and counts the pixels outside the common case (fewer than
``POISSON_EXACT_BELOW_E`` electrons, or within 6 sigma of the full well). A pair loop draws two normals per
64-bit hash (``rollcam.sim._rng``: pixel j and pixel j + W/2 of the row share one hash); the common loop is
``mean + spread * z`` rounded and clipped. Only rows that have uncommon pixels take the exact per-pixel pass
(float64: Poisson by inversion, clips at the full well and the ADC), drawing on a second hash per pixel.

``_plan`` runs ``_prep_row`` once over a static composite (a read-only ``LinearFrame.static``): a frame then
reads two float32 per static pixel, and computes only its painted lines. ``_prep_row`` is compiled without
fastmath, so a line gives the same values bit for bit from the plan or computed afresh.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._jitcache import guard
from ._rng import GOLD, mix, normal_pair, uniform

POISSON_EXACT_BELOW_E = 30.0
# Scalars of one exposure, in this order, in the float64 array ``p`` the kernels take.
P_QE, P_FLUX, P_DARK, P_VAR_READ, P_K, P_BLACK, P_FULL_WELL, P_READ, P_MAX_DN = range(9)


@njit(cache=True, parallel=True)
def fixed_patterns(fp_key, oy, ox, array_w, prnu, dsnu_e, gain_map, off_map):
    """PRNU gain (1 + prnu * N) and DSNU offset (dsnu * N, electrons) of each pixel, from its array position."""
    h, w = gain_map.shape
    for y in prange(h):
        row_idx = np.uint64((y + oy) * array_w + ox)
        for x in range(w):
            z_gain, z_off = normal_pair(mix(fp_key + (row_idx + np.uint64(x)) * GOLD))
            gain_map[y, x] = max(1.0 + prnu * z_gain, 0.0)
            off_map[y, x] = dsnu_e * z_off


@njit(cache=True, inline="always")
def _radiance(lin, ln, al, mono, ch):
    """Radiance a pixel's filter passes: channel ``ch`` of its Bayer colour, or luma for a mono sensor."""
    if mono:
        return 0.2126 * lin[ln, al, 0] + 0.7152 * lin[ln, al, 1] + 0.0722 * lin[ln, al, 2]
    return lin[ln, al, ch]


@njit(cache=True, parallel=True)
def mosaic(lin, by_col, cfa, mono, out):
    """out[y, x] = the radiance pixel (y, x)'s filter passes, from ``lin`` in render orientation."""
    h, w = out.shape
    for y in prange(h):
        for x in range(w):
            ln, al = np.int64(y), np.int64(x)
            if by_col:
                ln, al = np.int64(x), np.int64(y)
            out[y, x] = _radiance(lin, ln, al, mono, cfa[y & 1, x & 1])


@njit(cache=True)
def _row_radiance(lin, y, mono, cfa, out):
    """out[x] = filtered radiance of row ``y`` from ``lin`` in row orientation (even/odd columns apart)."""
    w = out.shape[0]
    if mono:
        for x in range(w):
            out[x] = 0.2126 * lin[y, x, 0] + 0.7152 * lin[y, x, 1] + 0.0722 * lin[y, x, 2]
        return
    for dx in range(2):
        ch = cfa[y & 1, dx]
        for x in range(dx, w, 2):
            out[x] = lin[y, x, ch]


@njit(cache=True)
def _col_radiance(lin, y, mono, cfa, out, x_from_over, over_flag):
    """Like ``_row_radiance`` for column-major ``lin`` (line = x), only where use_over[x] == over_flag."""
    for x in range(out.shape[0]):
        if x_from_over[x] == over_flag:
            out[x] = _radiance(lin, np.int64(x), np.int64(y), mono, cfa[y & 1, x & 1])


@njit(cache=True)
def _fill_radiance(y, base, mos, over, use_over, by_col, cfa, mono, mu_row):
    """mu_row = filtered radiance of output row ``y``: from ``over`` on painted lines, else ``mos`` or ``base``."""
    w = mu_row.shape[0]
    if by_col:
        _col_radiance(over, y, mono, cfa, mu_row, use_over, True)
        if mos.shape[0] > 0:
            for x in range(w):
                if not use_over[x]:
                    mu_row[x] = mos[y, x]
        else:
            _col_radiance(base, y, mono, cfa, mu_row, use_over, False)
    elif use_over[y]:
        _row_radiance(over, y, mono, cfa, mu_row)
    elif mos.shape[0] > 0:
        for x in range(w):
            mu_row[x] = mos[y, x]
    else:
        _row_radiance(base, y, mono, cfa, mu_row)


@njit(cache=True)  # no fastmath: the plan and a fresh line must agree bit for bit
def _prep_row(mu_row, gain_row, off_row, p, sat, m_row, s_row):
    """Radiance -> mean electrons (in ``mu_row``), mean DN and noise spread DN; returns the uncommon pixels."""
    qe, flux, dark, var_read, k = p[P_QE], p[P_FLUX], p[P_DARK], p[P_VAR_READ], p[P_K]
    black, full_well = p[P_BLACK], p[P_FULL_WELL]
    n = 0
    for x in range(mu_row.shape[0]):  # x * 1.0 and x + 0.0 are exact: the same values as separate optional steps
        mu = qe * max(mu_row[x], 0.0) * flux * gain_row[x] + dark
        mu_row[x] = mu
        off = off_row[x]
        m_row[x] = np.float32((mu + off) * k + black)
        s_row[x] = np.float32(math.sqrt(max(mu, 0.0) + var_read) * k)
        room = full_well - mu - off  # mu + off + 6 sqrt(mu) < full_well, without the square root
        n += (mu < POISSON_EXACT_BELOW_E) | (sat & ((room <= 0.0) | (36.0 * mu >= room * room)))
    return n


@njit(cache=True, parallel=True)
def plan(base, cfa, mono, on, gain_map, off_map, p, plan_m, plan_s, plan_n):
    """``_prep_row`` of every row of a static composite (row readout), kept for the frames that show it."""
    h, w = plan_m.shape
    no_lines, no_mos = np.zeros(h, np.bool_), np.empty((0, 0), np.float32)
    ones, zeros = np.ones(w, np.float32), np.zeros(w, np.float32)
    for y in prange(h):
        mu_row = np.empty(w)
        _fill_radiance(y, base, no_mos, base, no_lines, False, cfa, mono, mu_row)
        plan_n[y] = _prep_row(mu_row, gain_map[y] if on[4] else ones, off_map[y] if on[3] else zeros, p, on[5],
                              plan_m[y], plan_s[y])


@njit(cache=True, inline="always")
def _dn(e, k_dn, black, max_dn):
    """Electrons -> ADC sample: round half up, then clip (on the clipped, non-negative value truncation floors)."""
    return np.uint16(np.int64(min(max(e * k_dn + black + 0.5, 0.0), max_dn)))


@njit(cache=True, inline="always")
def _pair_normals(key, row_idx, nrm_row):
    """A normal per pixel of the row: pixel j and j + W // 2 share the pair of hash ``row_idx + j``."""
    w = nrm_row.shape[0]
    half = w // 2
    for j in range(half):
        nrm_row[j], nrm_row[j + half] = normal_pair(mix(key + (row_idx + np.uint64(j)) * GOLD))
    if w & 1:
        nrm_row[w - 1] = normal_pair(mix(key + (row_idx + np.uint64(half)) * GOLD))[0]


@njit(cache=True, parallel=True, fastmath=True)
def expose(base, mos, over, use_over, by_col, cfa, mono, p, frame_key, rest_key, oy, ox, array_w, on,
           gain_map, off_map, plan_m, plan_s, plan_n, out_int, out_f, quantize):
    """The per-pixel model; ``on`` = flags (shot, dark, read, dsnu, prnu, saturation).

    Radiance of line ``ln`` (row, or column when ``by_col``; arrays in render orientation) is read from
    ``over`` where ``use_over[ln]``, else from ``base`` (or from ``mos``, ``base`` through the colour filter,
    when not empty): a frame held as a static composite plus painted lines. A non-empty ``plan_m`` is the
    static composite's ``plan``, read on rows that are not painted (row readout only).
    """
    h, w = out_int.shape if quantize else out_f.shape
    shot, read, dsnu_on, prnu_on, sat = on[0], on[2], on[3], on[4], on[5]
    draw = shot or read  # the per-pixel hash feeds only the temporal draws
    has_plan = plan_m.shape[0] > 0 and not by_col
    k_dn, black, full_well, read_e, max_dn = p[P_K], p[P_BLACK], p[P_FULL_WELL], p[P_READ], p[P_MAX_DN]
    top = np.float32(max_dn)
    n_chunks = min(h, 64)
    ones, zeros = np.ones(w, np.float32), np.zeros(w, np.float32)
    for chunk in prange(n_chunks):
        mu_row, nrm_row = np.empty(w), np.empty(w, np.float32)
        mb, sb = np.empty(w, np.float32), np.empty(w, np.float32)
        for y in range(chunk, h, n_chunks):
            gain_row = gain_map[y] if prnu_on else ones
            off_row = off_map[y] if dsnu_on else zeros
            fresh = not has_plan or use_over[y]
            if fresh:
                _fill_radiance(y, base, mos, over, use_over, by_col, cfa, mono, mu_row)
                n_rest = _prep_row(mu_row, gain_row, off_row, p, sat, mb, sb)
                m_row, s_row = mb, sb
            else:
                n_rest, m_row, s_row = plan_n[y], plan_m[y], plan_s[y]
            row_idx = np.uint64((y + oy) * array_w + ox)
            if draw:
                _pair_normals(frame_key, row_idx, nrm_row)
            # The common case for every pixel in one straight loop: shot and read noise as one Gaussian of
            # summed variance (exact where mu >= POISSON_EXACT_BELOW_E and 6 sigma below the full well).
            if shot:
                if quantize:
                    for x in range(w):
                        v = m_row[x] + s_row[x] * nrm_row[x] + np.float32(0.5)
                        out_int[y, x] = np.uint16(np.int32(min(max(v, np.float32(0.0)), top)))
                else:
                    for x in range(w):
                        out_f[y, x] = np.float64(m_row[x] + s_row[x] * nrm_row[x])
                if n_rest == 0:
                    continue
            if not fresh:  # an uncommon pixel in a planned row: its electrons, exactly
                _fill_radiance(y, base, mos, over, use_over, by_col, cfa, mono, mu_row)
                _prep_row(mu_row, gain_row, off_row, p, sat, mb, sb)
            for x in range(w):
                mu, off = mu_row[x], off_row[x]
                room = full_well - mu - off
                if shot and mu >= POISSON_EXACT_BELOW_E and (not sat or (room > 0.0 and 36.0 * mu < room * room)):
                    continue
                z = nrm_row[x] if draw else 0.0
                h2 = mix(rest_key + (row_idx + np.uint64(x)) * GOLD)  # draws of this pixel's exact pass
                if shot and mu < POISSON_EXACT_BELOW_E:
                    e = _poisson(max(mu, 0.0), uniform(h2))  # ... and z is free for the read noise
                elif shot:
                    e = mu + math.sqrt(mu) * z
                    z = normal_pair(h2)[0]
                else:
                    e = mu
                e += off
                if sat:
                    # The well holds at most the full well. No clip at 0: the DSNU offset is relative to the
                    # mean dark signal, so a dark pixel may read below it; the black level keeps that visible
                    # and the ADC clips at 0 DN (``_dn``).
                    e = min(e, full_well)
                if read:
                    e += read_e * z
                if quantize:
                    out_int[y, x] = _dn(e, k_dn, black, max_dn)
                else:
                    out_f[y, x] = e * k_dn + black


@njit(cache=True, inline="always")
def _poisson(lam, u):
    p = math.exp(-lam)
    cdf = p
    k = 0
    while u > cdf and k < 1000:
        k += 1
        p *= lam / k
        cdf += p
    return float(k)


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
