"""Photon transfer: configured system gain, read noise and full well recovered from emu: frames alone."""

from __future__ import annotations

import pytest
from rollcam.benchmarks.ptc import format_ptc, measure_ptc, plot_ptc
from rollcam.common.errors import ConfigError
from rollcam.sim.hwconfig import load_sensor


@pytest.mark.parametrize("sensor", ["imx219", "ov9281", "imx477"])
def test_ptc_recovers_the_configured_figures(sensor):
    r = measure_ptc(sensor, size=(192, 144), steps=20)
    err = r.errors()
    assert abs(err["gain"]) < 0.02, format_ptc(r)
    assert abs(err["read_noise"]) < 0.05, format_ptc(r)
    assert abs(err["full_well"]) < 0.01, format_ptc(r)
    # EMVA's saturation point (maximum variance) sits a few shot-noise sigmas below the full well.
    assert 0.9 * r.full_well_configured < r.saturation_capacity_e < r.full_well_configured


def test_ptc_normalises_by_the_applied_gain_and_flags_an_adc_limit():
    # IMX708's analog gain starts at 1.123, and at that gain its ADC tops out before the full well.
    r = measure_ptc("imx708", size=(192, 144), steps=20)
    cfg = load_sensor("imx708")
    assert r.applied_gain == pytest.approx(1.123)
    assert abs(r.errors()["gain"]) < 0.02 and abs(r.errors()["read_noise"]) < 0.05
    adc_full_e = ((1 << cfg.bit_depth) - 1 - cfg.noise.black_level_dn) / (cfg.noise.system_gain_dn_per_e * 1.123)
    assert r.adc_limited and r.full_well_e == pytest.approx(adc_full_e, rel=0.01)


def test_ptc_plot_and_bad_steps(tmp_path):
    r = measure_ptc("imx219", size=(64, 48), steps=8)
    plot_ptc(r, tmp_path / "ptc.png")
    assert (tmp_path / "ptc.png").stat().st_size > 10_000
    with pytest.raises(ConfigError, match="4 exposure steps"):
        measure_ptc("imx219", steps=2)
