"""Walker surface texture, faces and shadows for the span painter of ``lines``: value noise
fixed to a part's axis, the features of a head seen from the camera, and the ground shadows' darkening."""

from __future__ import annotations

import math

from numba import njit

from .._jitcache import guard

SH_GEO, SH_TEX, SH_FACE, SHADE_COLS = 8, 13, 16, 21
"""Columns of a span's shading record after the eight of Q_LX, Q_LZ, ambient and direct RGB: the capsule's axis
and radius (Q_GEO..Q_GEO+4), texture contrast, cells per pixel and seed, then a head's face (Q_FACE: cos, sin;
Q_HAIR: hair over skin albedo, RGB)."""
SHADOW_MARK = -9.0
"""shade[m, 0] of a shadow's span (a body part's there, its Q_LX, lies in [-1, 1]; see ``darken``)."""
EYE_X, EYE_Y, EYE_RX, EYE_RY = 0.34, 0.12, 0.13, 0.075
BROW_Y, BROW_RX, BROW_RY = 0.29, 0.18, 0.04
MOUTH_Y, MOUTH_RX, MOUTH_RY = -0.43, 0.2, 0.05
"""Face features on a unit head sphere, in head radii from its centre (x across the face, y up): eyes (their
socket's shadow and iris, darkened), brows (hair-coloured), mouth (darkened); proportions of an adult face."""


@njit(cache=True, inline="always")
def _face(x, y, half_len, c, s):
    """What a head shows at (x, y) (head radii from its centre, y up; ``half_len`` the straight part's half
    length): (albedo factor, hair) for a face looking (cos c, sin s) from the camera. Hair covers the back and
    the top of the head above the hairline; the face has eyes, brows and a mouth."""
    ys = y - min(max(y, -half_len), half_len)  # on the capsule's cap spheres, or its straight middle
    q = 1.0 - x * x - ys * ys
    if q <= 0.0:
        return 1.0, False
    z = math.sqrt(q)
    xf = x * c - z * s  # across the face
    zf = x * s + z * c  # out of the face (> 0: its front half)
    if ys > 0.45 + 0.1 * xf * xf or (zf < -0.05 and ys > -0.6) or (abs(xf) > 0.8 and ys > -0.1 and zf < 0.5):
        return 1.0, True
    if zf < 0.3:
        return 1.0, False
    for ex in (-EYE_X, EYE_X):
        dx = (xf - ex) / BROW_RX
        dy = (y - BROW_Y) / BROW_RY
        if dx * dx + dy * dy < 1.0:
            return 1.0, True
        dx = (xf - ex) / EYE_RX
        dy = (y - EYE_Y) / EYE_RY
        if dx * dx + dy * dy < 1.0:
            return 0.35, False
    dx, dy = xf / MOUTH_RX, (y - MOUTH_Y) / MOUTH_RY
    if dx * dx + dy * dy < 1.0:
        return 0.6, False
    return 1.0, False


@njit(cache=True, inline="always")
def _lattice(ix, iy, seed):
    """A value in [0, 1) for lattice point (ix, iy) of texture ``seed``: an integer hash (murmur3's finaliser)."""
    h = (ix * 0x27D4EB2F + iy * 0x165667B1 + seed * 0x9E3779B1) & 0xFFFFFFFF
    h ^= h >> 15
    h = (h * 0x85EBCA6B) & 0xFFFFFFFF
    h ^= h >> 13
    h = (h * 0xC2B2AE35) & 0xFFFFFFFF
    h ^= h >> 16
    return h * (1.0 / 4294967296.0)


@njit(cache=True, inline="always")
def _cell(ix, iy, seed):
    """The four lattice values around cell (ix, iy) of texture ``seed``: (ix, iy), (ix+1, iy), (ix, iy+1),
    (ix+1, iy+1)."""
    return (_lattice(ix, iy, seed), _lattice(ix + 1, iy, seed), _lattice(ix, iy + 1, seed),
            _lattice(ix + 1, iy + 1, seed))


@njit(cache=True, inline="always")
def _smooth(x, y, cell):
    """Smooth value noise in [-1, 1] at lattice coordinates (x, y) from ``cell``, the lattice values of the cell
    holding (x, y) (``_cell``): smoothstep between them."""
    tx, ty = x - math.floor(x), y - math.floor(y)
    tx, ty = tx * tx * (3.0 - 2.0 * tx), ty * ty * (3.0 - 2.0 * ty)
    a = cell[0] + tx * (cell[1] - cell[0])
    b = cell[2] + tx * (cell[3] - cell[2])
    return 2.0 * (a + ty * (b - a)) - 1.0


@njit(cache=True, inline="always")
def _value_noise(x, y, seed):
    """Smooth value noise in [-1, 1] at lattice coordinates (x, y): smoothstep between hashed lattice values."""
    return _smooth(x, y, _cell(int(math.floor(x)), int(math.floor(y)), seed))


@njit(cache=True, inline="always")
def texture_span(shade, e, flip):
    """The per-span constants of ``texture_at`` for span ``e``: the part's axis start and unit direction, its
    length, the texture's cells per pixel, contrast and seed, and the head's radius and face record (a head
    when ``face``). Computed once per span: per pixel they were most of the texture's cost."""
    if not shade[e, SH_TEX] > 0.0:  # untextured: its texture columns were never written
        return 0.0, 0.0, 0.0, 1.0, 0.0, flip, 0.0, 0.0, 0, False, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0
    ax, ay, bx, by = shade[e, SH_GEO], shade[e, SH_GEO + 1], shade[e, SH_GEO + 2], shade[e, SH_GEO + 3]
    dx, dy = bx - ax, by - ay
    ln = math.sqrt(dx * dx + dy * dy)
    if ln > 0.0:
        dx, dy = dx / ln, dy / ln
    else:
        dx, dy = 0.0, 1.0
    face = not shade[e, SH_FACE] < -1.0
    return (ax, ay, dx, dy, ln, flip, shade[e, SH_TEX + 1], shade[e, SH_TEX], int(shade[e, SH_TEX + 2]),
            face, shade[e, SH_GEO + 4], shade[e, SH_FACE], shade[e, SH_FACE + 1], shade[e, SH_FACE + 2],
            shade[e, SH_FACE + 3], shade[e, SH_FACE + 4])


NO_CELL = (0, 0, False, 0.0, 0.0, 0.0, 0.0)
"""``texture_at``'s cell cache holding no cell (a new span's)."""


@njit(cache=True, inline="always")
def texture_at(ts, x, yc, cell):
    """Albedo factors (R, G, B) at render-space point (x, yc) of the span whose ``texture_span`` is ``ts``,
    and the cell cache for the next pixel: 1 + contrast x value noise in coordinates fixed to the part's axis
    (along it from its first end, across it from its axis), so the texture travels with the part, and on a
    head its face and hair. The ``flip`` in ``ts`` (-1 for a transposed render) keeps the across coordinate the
    image's, whichever way lines run.

    ``cell`` (cell x, cell y, valid, its four lattice values; ``NO_CELL`` for a span's first pixel) is the last
    pixel's cell: neighbouring pixels mostly share one, so the hashes are redone only when the cell changes.
    It is a tuple of scalars, not an array, so the per-pixel loop touches no reference counts.
    """
    ax, ay, dx, dy, ln, flip, k, contrast, seed, face, r, fc, fs, h0, h1, h2 = ts
    px, py = x - ax, yc - ay
    along_px = px * dx + py * dy
    across_px = (py * dx - px * dy) * flip
    nx, ny = across_px * k, along_px * k
    ix, iy = int(math.floor(nx)), int(math.floor(ny))
    if not cell[2] or cell[0] != ix or cell[1] != iy:
        c = _cell(ix, iy, seed)
        cell = (ix, iy, True, c[0], c[1], c[2], c[3])
    f = 1.0 + contrast * _smooth(nx, ny, (cell[3], cell[4], cell[5], cell[6]))
    if not face:
        return f, f, f, cell
    g, hair = _face(across_px / r, (along_px - 0.5 * ln) / r, 0.5 * ln / r, fc, fs)
    if hair:
        return f * h0, f * h1, f * h2, cell
    return f * g, f * g, f * g, cell


@njit(cache=True)
def darken(lin, line, shade, e, xl, xr, i0, i1):
    """A shadow's span: what is painted under it keeps ``1 - s min(1, edge (1 - r^2))^2`` of its light per
    channel (see ``parts.shadow_part``). Its shade row: SHADOW_MARK at 0, the strengths at 2..4,
    the edge at 5, the centre at SH_GEO and the inverse shape matrix at SH_GEO + 2.. and 1."""
    cx, cy = shade[e, SH_GEO], shade[e, SH_GEO + 1]
    n00, n01, n10, n11 = shade[e, SH_GEO + 2], shade[e, SH_GEO + 3], shade[e, SH_GEO + 4], shade[e, 1]
    edge = shade[e, 5]
    dv = line + 0.5 - cy
    for i in range(i0, i1):
        cov = min(xr, i + 1.0) - max(xl, float(i))
        if cov <= 0.0:
            continue
        du = i + 0.5 - cx
        ra, rb = n00 * du + n01 * dv, n10 * du + n11 * dv
        q = min(edge * (1.0 - ra * ra - rb * rb), 1.0)
        if q <= 0.0:
            continue
        q = cov * q * q
        for c in range(3):
            lin[i, c] = lin[i, c] * (1.0 - shade[e, 2 + c] * q)


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
