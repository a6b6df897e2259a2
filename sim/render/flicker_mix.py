"""Numba kernel that joins a modulated-light render: per-line weighted sums of light renders, then 8-bit encoding.

Part of ``flicker_renderer``: a frame under modulated light is the steady light's render plus each
modulated light's render scaled, line by line, by that light's mean over the line's exposure window. Each
render arrives as the renderer's ``LinearFrame`` parts (a shared static composite and the lines painted over
it), stacked part by part. Every path (frame, sensor radiance, exposure integration, brute-force reference) joins
its renders through this same kernel, in the same order, so they stay comparable bit for bit.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .._jitcache import guard
from .lines import encode_line


@njit(cache=True, parallel=True)
def join_lines(dst, statics, lines, painted, weight, which, gain, lut, out_u8):
    """``dst[l] = sum_k weight[k, l] * render_k[l]`` for each line ``l`` in ``which`` (render k's line is
    ``lines[k, l]`` if ``painted[k, l]`` else ``statics[k, l]``), in float32 and part order; then, when
    ``out_u8`` is not empty, that line through the renderer's own output curve (``lines.encode_line``)
    while it is still in cache. One pass over the frame, whatever the part count. Every array is C-contiguous:
    a line is one flat run the compiler vectorises."""
    n_parts = lines.shape[0]
    want_u8 = out_u8.shape[0] > 0
    for j in prange(which.shape[0]):
        ln = which[j]
        d = dst[ln].reshape(-1)
        for k in range(n_parts):
            src = (lines[k, ln] if painted[k, ln] else statics[k, ln]).reshape(-1)
            g = np.float32(weight[k, ln])
            if k == 0:
                for i in range(d.shape[0]):
                    d[i] = g * src[i]
            else:
                for i in range(d.shape[0]):
                    d[i] += g * src[i]
        if want_u8:
            encode_line(dst[ln], gain, lut, out_u8[ln])


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
