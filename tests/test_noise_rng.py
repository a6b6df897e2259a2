"""The sensor model's counter-based normals (rollcam.sim._rng) and what the noise depends on."""

from __future__ import annotations

import math

import numpy as np
from rollcam.common.mixing import GOLDEN, MASK64, finalise, splitmix64
from rollcam.sim._rng import log_f32, mix, normals
from rollcam.sim.hwconfig import load_sensor
from rollcam.sim.noise import SensorModel
from scipy import stats


def test_normal_pairs_are_standard_normal_and_independent():
    z = normals(np.uint64(2024), np.arange(1_000_000, dtype=np.uint64)).astype(np.float64)
    n = z.size
    assert abs(z.mean()) < 4 / math.sqrt(n)
    assert abs(z.var() - 1) < 4 * math.sqrt(2 / n)
    assert abs(stats.skew(z)) < 4 * math.sqrt(6 / n) and abs(stats.kurtosis(z)) < 4 * math.sqrt(24 / n)
    assert stats.kstest(z, "norm").pvalue > 1e-3
    for t in (2.0, 3.0, 4.0):  # the tails, not just the bulk
        tail = np.mean(np.abs(z) > t)
        expected = 2 * stats.norm.sf(t)
        assert abs(tail - expected) < 5 * math.sqrt(expected / n), t
    assert np.abs(z).max() > 4.5  # no truncation at a table's end
    a, b = z[0::2], z[1::2]  # the two of a pair: uncorrelated, and so are their squares (Box-Muller's radius)
    assert abs(np.corrcoef(a, b)[0, 1]) < 4 / math.sqrt(n / 2)
    assert abs(np.corrcoef(a * a, b * b)[0, 1]) < 4 / math.sqrt(n / 2)


def test_log_is_accurate_over_the_range_the_radius_uses():
    x = np.geomspace(2.0 ** -33, 1.0, 20_001).astype(np.float32)
    got = np.array([log_f32(v) for v in x[::200]], np.float64)
    np.testing.assert_allclose(got, np.log(x[::200].astype(np.float64)), rtol=2e-6, atol=2e-7)


def test_temporal_noise_of_a_pixel_depends_on_seed_frame_and_pixel_only():
    """Changing the radiance of some pixels leaves every other pixel's draw (hence DN) where it was."""
    m = SensorModel(load_sensor("imx219").noise, 10, "RGGB", serial="Z", seed=4)
    flat = np.full((48, 64, 3), 0.4, np.float32)
    other = flat.copy()
    other[10:20, 5:40] = 0.8
    a, b = m.expose(flat, 10_000_000, 7), m.expose(other, 10_000_000, 7)
    same = np.ones(a.shape, bool)
    same[10:20, 5:40] = False
    np.testing.assert_array_equal(a[same], b[same])
    assert not np.array_equal(a[~same], b[~same])
    # and the draws of frame 7 do not depend on frames drawn before it
    m.expose(flat, 10_000_000, 3)
    np.testing.assert_array_equal(m.expose(flat, 10_000_000, 7), a)


def test_the_kernels_mixer_is_common_splitmix64():
    """sim._rng's numba ``mix`` and common.mixing's ``finalise`` are one function; ``splitmix64`` is the
    reference generator's output (Vigna's splitmix64.c from state 0: e220a8397b1dcdaf, 6e789e6aa1b965f4, ...)."""
    words = np.random.default_rng(38).integers(0, 2**64, size=4096, dtype=np.uint64)
    assert [int(mix(w)) for w in words] == [finalise(int(w)) for w in words]
    assert [splitmix64(k * GOLDEN & MASK64) for k in range(3)] == [0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4,
                                                                   0x06C45D188009454F]
