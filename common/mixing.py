"""SplitMix64, the one mixer of rollcam's counter-based random numbers: its constants and its finaliser.

A draw is ``finalise(key + counter * GOLDEN)``, a function of (key, counter) alone, so any draw can be made without
the ones before it. The fault plan mixes Python integers here; the sensor model's numba kernels
(``rollcam.sim._rng``) take the same constants as uint64 and run the same finaliser over whole rows.
"""

from __future__ import annotations

GOLDEN = 0x9E3779B97F4A7C15
"""SplitMix64's counter step: 2**64 divided by the golden ratio, rounded to odd."""
MUL1 = 0xBF58476D1CE4E5B9
"""The finaliser's first multiplier."""
MUL2 = 0x94D049BB133111EB
"""The finaliser's second multiplier."""
MASK64 = (1 << 64) - 1
"""A 64-bit word's bits: Python integers are cut to this after each step, as uint64 arithmetic wraps."""


def finalise(z: int) -> int:
    """SplitMix64's finaliser: a 64-bit word -> 64 well-mixed bits (a bijection)."""
    z &= MASK64
    z = ((z ^ (z >> 30)) * MUL1) & MASK64
    z = ((z ^ (z >> 27)) * MUL2) & MASK64
    return z ^ (z >> 31)


def splitmix64(state: int) -> int:
    """The output of SplitMix64 whose state is ``state`` before the step: ``finalise(state + GOLDEN)``."""
    return finalise(state + GOLDEN)
