"""Numba kernels of the IMU's noise: counter-based white noise and bias random walks, by sample index.

Every draw is a standard normal from the image noise's counter-based generator (``rollcam.sim._rng``:
SplitMix64 and a Box-Muller pair) keyed by (seed key, stream, level, index), so sample ``k`` depends only on the
seed and ``k``, never on which samples were drawn before. A random walk is made random-access the same way: ``walk(n)``
is a unit-step Gaussian random walk (``W(0) = 0``, ``W(n) - W(n-1) ~ N(0, 1)`` independent) built as a
Brownian bridge on a dyadic tree of ``WALK_LEVELS`` levels: the value at the end of the span, then each
midpoint from its interval's ends plus a keyed normal of the bridge's variance. ``walk(n)`` costs one draw per
level, whatever ``n`` is (2**48 samples: 4,460 years at 2 kHz), and the increments are exactly independent
N(0, 1), as Brownian motion sampled at the integers is.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._jitcache import guard
from ._rng import GOLD, mix, normal_pair

WALK_LEVELS = 48


@njit(cache=True, inline="always")
def _z(key, stream, level, index):
    """One standard normal for (key, stream, level, index)."""
    h = mix(key ^ (np.uint64(stream * 64 + level + 1) * GOLD))
    h = mix(h ^ (np.uint64(index) * GOLD + np.uint64(0x632BE59BD9B4E019)))
    return float(normal_pair(h)[0])


@njit(cache=True)
def _walk(key, stream, n):
    """W(n) of the keyed unit-step random walk (see the module docstring)."""
    a, b = 0, 1 << WALK_LEVELS
    wa, wb = 0.0, math.sqrt(float(b)) * _z(key, stream, WALK_LEVELS, 0)
    for level in range(WALK_LEVELS, 0, -1):
        if n == a:
            return wa
        if n == b:
            return wb
        m = a + (1 << (level - 1))
        wm = 0.5 * (wa + wb) + 0.5 * math.sqrt(float(1 << level)) * _z(key, stream, level - 1, a >> level)
        if n < m:
            b, wb = m, wm
        else:
            a, wa = m, wm
    return wa if n == a else wb


@njit(cache=True, parallel=True)
def white_and_walk(key, first, count, white_stream, walk_stream, white, walk):
    """Fill ``white`` and ``walk`` (count, 3) with unit white noise and unit random walks of samples
    ``first .. first + count - 1``, axis ``i`` on streams ``white_stream + i`` and ``walk_stream + i``."""
    for j in prange(count):
        k = first + j
        for i in range(3):
            white[j, i] = _z(key, white_stream + i, 63, k)
            walk[j, i] = _walk(key, walk_stream + i, k)


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
