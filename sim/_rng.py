"""Counter-based random numbers for the sensor model's numba kernels: a draw depends only on its counter.

``mix`` is SplitMix64's finaliser: ``mix(key + counter * GOLDEN)`` turns a (key, counter) pair into 64
well-mixed bits, so the noise of frame n, pixel p is a function of (seed, n, p) alone and any pixel can be
drawn without the others. ``normal_pair`` turns those 64 bits into two independent standard normals by the
Box-Muller transform in float32: 32 bits give the radius ``sqrt(-2 ln u)`` (u in (0, 1], so |z| reaches 6.7),
2 bits the quadrant and 30 bits the angle within it. Logarithm, sine and cosine are polynomials written
here, branch-free (selects, not jumps), so a loop of draws vectorises: numba has no vector ``math.log``
without Intel's SVML. Errors against the exact transform are below 1e-6 (relative) everywhere.
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core.extending import intrinsic
from rollcam.common import mixing

from ._jitcache import guard

M1, M2, GOLD = np.uint64(mixing.MUL1), np.uint64(mixing.MUL2), np.uint64(mixing.GOLDEN)  # SplitMix64's, as uint64
_F = np.float32
_LN2 = 0.6931471805599453
_SQRT_HALF_2 = 1.4142135623730951  # the mantissa range [sqrt(2)/2, sqrt(2)) keeps |t| <= 0.172 below


@intrinsic
def _bits_of(typingctx, x):
    """The IEEE bits of a float32, as int32 (a bit cast: no conversion)."""
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(32))
    return types.int32(types.float32), codegen


@intrinsic
def _float_of(typingctx, i):
    """The float32 whose IEEE bits are int32 ``i``."""
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.FloatType())
    return types.float32(types.int32), codegen


@njit(cache=True, inline="always")
def mix(z):
    """SplitMix64's finaliser: 64 bits -> 64 well-mixed bits (a bijection)."""
    z = (z ^ (z >> np.uint64(30))) * M1
    z = (z ^ (z >> np.uint64(27))) * M2
    return z ^ (z >> np.uint64(31))


@njit(cache=True, inline="always")
def log_f32(x):
    """Natural log of a positive, finite float32: exponent from the bits, mantissa by the atanh series."""
    i = _bits_of(x)
    e = _F((i >> 23) - 127)
    m = _float_of((i & 0x7FFFFF) | 0x3F800000)  # in [1, 2)
    big = m > _F(_SQRT_HALF_2)
    m = m * _F(0.5) if big else m
    e = e + _F(1.0) if big else e
    t = (m - _F(1.0)) / (m + _F(1.0))  # log m = 2 atanh t; |t| <= 0.172, so t**11 / 11 is below float32's ulp
    t2 = t * t
    p = _F(2.0 / 7.0) + t2 * _F(2.0 / 9.0)
    p = _F(2.0 / 5.0) + t2 * p
    p = _F(2.0 / 3.0) + t2 * p
    p = _F(2.0) + t2 * p
    return e * _F(_LN2) + t * p


@njit(cache=True, inline="always")
def normal_pair(h):
    """Two independent standard normals (float32) from 64 random bits (Box-Muller)."""
    u = (_F(np.int64(h >> np.uint64(32))) + _F(0.5)) * _F(2.0 ** -32)  # (0, 1]
    r = math.sqrt(max(_F(-2.0) * log_f32(u), _F(0.0)))
    q = np.int64(h >> np.uint64(30)) & 3
    a = (_F(np.int64(h & np.uint64(0x3FFFFFFF))) * _F(2.0 ** -30) - _F(0.5)) * _F(math.pi / 2)  # [-pi/4, pi/4)
    a2 = a * a
    c = _F(1.0) + a2 * (_F(-0.5) + a2 * (_F(1 / 24) + a2 * (_F(-1 / 720) + a2 * _F(1 / 40320))))
    s = a * (_F(1.0) + a2 * (_F(-1 / 6) + a2 * (_F(1 / 120) + a2 * _F(-1 / 5040))))
    # The angle q * pi/2 + a is uniform on the circle: rotate (cos a, sin a) by q quarter turns.
    swap = (q & 1) == 1
    sign = _F(1 - (q & 2))
    return r * (-s if swap else c) * sign, r * (c if swap else s) * sign


@njit(cache=True, inline="always")
def uniform(h):
    """A uniform float64 in [0, 1) from the high 32 of 64 random bits."""
    return float(np.int64(h >> np.uint64(32))) * (1.0 / 4294967296.0)


@njit(cache=True)
def normals(key, counters):
    """``2 * len(counters)`` normals, the pairs of ``mix(key + c * GOLD)`` in order (for tests and studies)."""
    out = np.empty(2 * counters.size, np.float32)
    for i in range(counters.size):
        out[2 * i], out[2 * i + 1] = normal_pair(mix(key + np.uint64(counters[i]) * GOLD))
    return out


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
