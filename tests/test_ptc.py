"""Photon transfer: configured gain, read noise, full well, DSNU and dark current recovered from emu: frames alone."""

from __future__ import annotations

import numpy as np
import pytest
from rollcam.benchmarks.ptc import analyse_emva, capture_emva, format_ptc, measure_ptc, plot_ptc
from rollcam.common.errors import ConfigError
from rollcam.sim.hwconfig import load_sensor


@pytest.mark.parametrize("sensor", ["imx219", "ov9281", "imx477"])
def test_ptc_recovers_the_configured_figures(sensor):
    r = measure_ptc(sensor, size=(192, 144), steps=20)
    err = r.errors()
    # At this size each figure's error spreads by about 0.5 % from seed to seed (imx219, 10 seeds: mean gain
    # error -0.03 %, sd 0.55 %; full well -0.11 %, sd 0.56 %), so 2 % is four standard deviations.
    assert abs(err["gain"]) < 0.02, format_ptc(r)
    assert abs(err["read_noise"]) < 0.05, format_ptc(r)
    assert abs(err["full_well"]) < 0.02, format_ptc(r)
    # Dark frames at exposures up to ~1 s (regression: negative DSNU offsets were clipped at 0 e-, which read
    # DSNU 0.61 e- for 1.0 and dark current 7.1 e-/s for 10).
    assert abs(err["dsnu"]) < 0.05, format_ptc(r)
    assert abs(err["dark_current"]) < 0.05, format_ptc(r)
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


def _reference_results(c, path):
    """The EMVA 1288 reference implementation's results on captures ``c``, fed to it as image files."""
    from emva1288.process import Data1288, LoadImageData, Results1288

    def save(name, img):
        np.save(path / name, img.astype(np.int64))
        return name

    temporal = {}
    for i, p in enumerate(c.points):
        photons = c.level * p.exposure_ns  # proportional to photons: only QE and R (unchecked) use the scale
        temporal[p.exposure_ns] = {
            0.0: [save(f"t{i}d{j}.npy", f) for j, f in enumerate(p.dark)],
            photons: [save(f"t{i}b{j}.npy", f) for j, f in enumerate(p.bright)]}
    spatial = {c.stack_exposure_ns: {
        0.0: [save(f"sd{j}.npy", f) for j, f in enumerate(c.dark_stack)],
        c.level * c.stack_exposure_ns: [save(f"sb{j}.npy", f) for j, f in enumerate(c.bright_stack)]}}
    loaded = LoadImageData({"temporal": temporal, "spatial": spatial}, path=str(path), fload=np.load,
                           loglevel=40)
    return Results1288(Data1288(loaded.data, loglevel=40).data, loglevel=40)


@pytest.mark.parametrize("sensor", ["imx219", "ov9281"])
def test_emva1288_reference_implementation_agrees_on_rollcams_captures(sensor, tmp_path, monkeypatch):
    """The EMVA 1288 reference (emva1288 on PyPI) run on the same dark and flat-field captures finds the
    configured DSNU, dark current and system gain, and agrees with the bench's own analysis."""
    pytest.importorskip("emva1288")
    # emva1288 1.0.2 calls np.asfarray, which NumPy 2 removed; give it back for the reference's fits.
    monkeypatch.setattr(np, "asfarray", lambda a, dtype=np.float64: np.asarray(a, dtype=dtype), raising=False)
    c = capture_emva(sensor, size=(160, 120), steps=16)
    ours = analyse_emva(c)
    ref = _reference_results(c, tmp_path)
    n = load_sensor(sensor).noise
    k_ref, dsnu_ref, dark_ref = ref.K / ours.applied_gain, ref.DSNU1288, ref.u_I_mean
    assert k_ref == pytest.approx(n.system_gain_dn_per_e, rel=0.02)
    assert dsnu_ref == pytest.approx(n.dsnu_e, rel=0.05)
    assert dark_ref == pytest.approx(n.dark_current_e_per_s, rel=0.05)
    assert ours.dsnu_e == pytest.approx(dsnu_ref, rel=0.01)
    assert ours.dark_current_e_per_s == pytest.approx(dark_ref, rel=0.01)
