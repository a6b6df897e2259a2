"""Numba kernels that join a modulated-light render: per-line weighted sums of light renders, then 8-bit encoding.

Part of ``rollcam.sim.flicker_render``: a frame under modulated light is the steady light's render plus each
modulated light's render scaled, line by line, by that light's mean over the line's exposure window. Each
render arrives as the renderer's ``LinearFrame`` parts (a shared static composite and the lines painted over
it), read in place. Every path (frame, sensor radiance, exposure integration, brute-force reference) joins its
renders through these same kernels, in the same order, so they stay comparable bit for bit.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._jitcache import guard
from ._kernels import encode_line


@njit(cache=True, inline="always")
def _add_line(d, src, g, first):
    for i in range(d.shape[0]):
        for c in range(3):
            v = g * np.float64(src[i, c])
            if not first:
                v += np.float64(d[i, c])
            d[i, c] = np.float32(v)


@njit(cache=True, parallel=True)
def add_lines(dst, static, lines, painted, weight, first, which):
    """``dst[l] (+)= weight[l] * render[l]`` for each line ``l`` in ``which``, where the render's line is
    ``lines[l]`` if ``painted[l]`` else ``static[l]``; ``first`` writes instead of adding. Sums in float64."""
    for j in prange(which.shape[0]):
        ln = which[j]
        if painted[ln]:
            _add_line(dst[ln], lines[ln], weight[ln], first)
        else:
            _add_line(dst[ln], static[ln], weight[ln], first)


@njit(cache=True, parallel=True)
def encode_lines(lin, which, gain, lut, out_u8):
    """8-bit BGR of each line in ``which`` through the renderer's own output curve (``_kernels.encode_line``)."""
    for j in prange(which.shape[0]):
        ln = which[j]
        encode_line(lin[ln], gain, lut, out_u8[ln])


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
