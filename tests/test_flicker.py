"""Light that changes in time: waveform means, rolling-shutter bands against the analytic values, global shutter."""

from __future__ import annotations

import math

import numpy as np
import pytest
from rollcam.common.errors import ConfigError
from rollcam.firmware.options import parse_options
from rollcam.sim.flicker import Waveform
from rollcam.sim.hwconfig import load_sensor
from rollcam.sim.render.flicker_renderer import FlickerRenderer
from rollcam.sim.render.renderer import Renderer
from rollcam.sim.scenegen import make_chart_scene, make_scene, make_street_scene
from rollcam.sim.synthetic import SyntheticCamera

SENSOR = load_sensor("imx219")
LINE_PCK = 3448 * 5  # a 94.5 us line: a 100 Hz lamp's bands are ~106 rows apart, four and a half in 480 rows
DAY_NS = 86_400 * 10**9


def _quad_mean(wave: Waveform, t0_s: float, width_s: float, n: int = 200_001) -> float:
    """Mean of the light over a window by the trapezoidal rule on the instantaneous value (no antiderivative)."""
    u = wave.freq_hz * (t0_s + np.linspace(0.0, width_s, n)) + wave.phase
    v = 1.0 - wave.depth + wave.depth * wave.shape_at(u)
    return float((v[:-1] + v[1:]).sum() / (2 * (n - 1)))


WAVES = [Waveform.mains("incandescent", 50.0, depth=0.6), Waveform.mains("sodium", 60.0),
         Waveform.mains("fluorescent", 50.0, phase=0.3), Waveform.pwm(400.0, 0.3, phase=0.55),
         Waveform.pwm(1234.5, 0.8)]


@pytest.mark.parametrize("wave", WAVES, ids=lambda w: w.describe())
def test_window_mean_is_the_integral_of_the_waveform(wave: Waveform) -> None:
    rng = np.random.default_rng(3)
    t0 = rng.integers(0, 10**9, 6)
    width = rng.integers(1, 40_000_000, 6)
    got = wave.window_mean(t0, t0 + width)
    want = [_quad_mean(wave, a * 1e-9, w * 1e-9) for a, w in zip(t0, width, strict=True)]
    # The trapezoidal rule's own error: ~1e-5 for smooth shapes, more at a PWM edge (a jump of 1 / duty).
    np.testing.assert_allclose(got, want, atol=2e-4 if wave.shape == "pwm" else 2e-5)
    # Whole periods average to the nominal level, wherever they start.
    period_ns = round(1e9 / wave.freq_hz)
    if period_ns * wave.freq_hz == 1e9:
        np.testing.assert_allclose(wave.window_mean(t0, t0 + 3 * period_ns), 1.0, atol=1e-12)
    # An empty window is the instantaneous value.
    np.testing.assert_allclose(wave.window_mean(t0, t0), wave.value(t0))


def test_window_mean_keeps_its_phase_after_thirty_days() -> None:
    wave = Waveform.mains("sodium", 50.0)  # 100 Hz: a period of exactly 10 ms
    t0 = np.array([1_234_567, 7_654_321])
    late = t0 + 30 * DAY_NS  # a whole number of periods later
    np.testing.assert_allclose(wave.window_mean(late, late + 2_500_000), wave.window_mean(t0, t0 + 2_500_000),
                               atol=1e-9)


def test_bad_waveforms_are_refused() -> None:
    for bad in (dict(shape="square", freq_hz=100.0), dict(shape="sine", freq_hz=0.0),
                dict(shape="sine", freq_hz=100.0, depth=1.5), dict(shape="pwm", freq_hz=100.0, duty=0.0)):
        with pytest.raises(ConfigError):
            Waveform(**bad)
    with pytest.raises(ConfigError, match="mains"):
        Waveform.mains("sodium", 55.0)
    with pytest.raises(ConfigError, match="lamp"):
        make_scene("flicker", lamp="candle")
    with pytest.raises(ConfigError, match="ends before"):
        WAVES[0].window_mean(np.array([10]), np.array([5]))


# ---------------------------------------------------------------------------------------------- bands on a wall
def _profile(scene, exposure_ns: int, shutter: str = "rolling", index: int = 0) -> tuple[np.ndarray, SyntheticCamera]:
    cam = SyntheticCamera(SENSOR, scene, size=(640, 480), line_length_pck=LINE_PCK, exposure_ns=exposure_ns,
                          shutter=shutter)
    res = cam.renderer.render_lines(cam.line_times_ns(index), linear=True)
    return res.linear[:, :, 1].astype(np.float64).mean(axis=1), cam


def _contrast(p: np.ndarray) -> float:
    return float((p.max() - p.min()) / (p.max() + p.min()))


def _period_rows(p: np.ndarray) -> float:
    """Mean spacing of the profile's upward crossings of its mid level (linear interpolation)."""
    mid = 0.5 * (p.max() + p.min())
    up = np.flatnonzero((p[:-1] < mid) & (p[1:] >= mid))
    x = up + (mid - p[up]) / (p[up + 1] - p[up])
    assert x.size >= 3, "need at least two band periods in the frame"
    return float(np.diff(x).mean())


def _pwm_contrast(duty: float, cycles: float) -> float:
    """Michelson contrast of a square wave (on ``duty``) averaged over a window of ``cycles`` periods."""
    n, r = math.floor(cycles), cycles - math.floor(cycles)
    hi = n * duty + min(r, duty)
    lo = n * duty + max(0.0, r - (1.0 - duty))
    return (hi - lo) / (hi + lo)


def _rectified_contrast(depth: float, cycles: float) -> float:
    """Contrast of (1 - d) + d (pi/2) |sin(pi u)| averaged over ``cycles`` periods, by quadrature."""
    u = np.linspace(0.0, cycles, 20_001)
    phases = np.linspace(0.0, 1.0, 801)
    v = 1 - depth + depth * 0.5 * math.pi * np.abs(np.sin(math.pi * (u[None, :] + phases[:, None])))
    g = (v[:, :-1] + v[:, 1:]).sum(axis=1) / (2 * (u.size - 1))
    return float((g.max() - g.min()) / (g.max() + g.min()))


def _analytic(scene, exposure_ns: int) -> float:
    wave = scene.lights[0].waveform
    cycles = wave.freq_hz * exposure_ns * 1e-9
    if wave.shape == "sine":
        return wave.depth * abs(math.sin(math.pi * cycles) / (math.pi * cycles))
    if wave.shape == "pwm":
        return _pwm_contrast(wave.duty, cycles)
    return _rectified_contrast(wave.depth, cycles)


CASES = [  # (scene options, exposures in ms: the last ones cover k / f, where the bands vanish)
    (dict(lamp="incandescent", lamp_depth=0.5), (1.0, 3.0, 7.0, 10.0, 20.0)),
    (dict(lamp="sodium"), (0.5, 4.0, 10.0)),
    (dict(lamp="halogen", mains_hz=60.0, lamp_depth=1.0), (2.0, 25.0 / 3.0)),
    (dict(lamp="led", led_hz=400.0, led_duty=0.3), (0.3, 1.0, 2.0, 5.0)),
]


@pytest.mark.parametrize(("options", "exposures_ms"), CASES, ids=lambda v: str(v))
def test_rolling_shutter_bands_match_the_analytic_period_and_contrast(options, exposures_ms) -> None:
    scene = make_scene("flicker", 0, width=640, height=480, **options)
    f = scene.lights[0].waveform.freq_hz
    for exp_ms in exposures_ms:
        prof, cam = _profile(scene, round(exp_ms * 1e6))
        exposure_ns = cam.settings.exposure_ns  # whole lines, as the sensor programs it
        want = _analytic(scene, exposure_ns)
        got = _contrast(prof)
        assert abs(got - want) <= 0.02 * want + 1e-3, (exp_ms, got, want)
        if want > 0.02:
            rows = 1e9 / (f * cam.settings.timing.line_time_ns)
            assert abs(_period_rows(prof) - rows) <= 1.0, (exp_ms, _period_rows(prof), rows)
        if abs(round(f * exposure_ns * 1e-9) - f * exposure_ns * 1e-9) < 0.01:
            assert got < 0.01, f"exposure {exposure_ns} ns covers whole periods: no bands, got contrast {got}"


def test_global_shutter_has_no_bands_but_frames_change_brightness() -> None:
    scene = make_scene("flicker", 0, width=640, height=480, lamp="sodium", level=0.4)
    means = []
    for i in range(3):
        prof, cam = _profile(scene, 2_000_000, "global", i)
        assert prof.max() - prof.min() <= 1e-6 * prof.mean()
        start = cam.timestamp_ns(i)
        e = cam.settings.exposure_ns
        want = 0.4 * scene.lights[0].waveform.window_mean(np.array([start]), np.array([start + e]))[0]
        assert prof.mean() == pytest.approx(want, rel=1e-5)
        means.append(prof.mean())
    assert max(means) - min(means) > 0.02 * np.mean(means), means


def test_sensor_path_integrates_each_row_over_its_window() -> None:
    """The physics path (exposure integration, ADC) shows the same bands as the radiance, to a DN."""
    scene = make_scene("flicker", 0, width=640, height=480, lamp="incandescent", lamp_depth=0.5, level=0.6)
    cam = SyntheticCamera(SENSOR, scene, size=(640, 480), line_length_pck=LINE_PCK, exposure_ns=3_000_000,
                          pixel_format="RG10", noise=frozenset())
    dn = cam.frame(0).data.astype(np.float64) - SENSOR.noise.black_level_dn
    prof = np.array([dn[r, (r + 1) % 2::2].mean() for r in range(dn.shape[0])])  # the green sites of RGGB
    want = _analytic(scene, cam.settings.exposure_ns)
    assert abs(_contrast(prof) - want) <= 0.02 * want + 2e-3
    rows = 1e9 / (100.0 * cam.settings.timing.line_time_ns)
    assert abs(_period_rows(prof) - rows) <= 1.0


# ---------------------------------------------------------------------------------------------- the street
def test_lamps_are_on_at_dusk_and_night_only() -> None:
    assert make_street_scene(0, time_of_day="noon", n_pedestrians=0, n_cameras=1).lights == ()
    night = make_street_scene(0, time_of_day="night", n_pedestrians=0, n_cameras=1)
    assert [li.name for li in night.lights] == ["street lamps", "signs"]
    assert night.lighting.window_glow == 0.0  # the signs carry the glow
    assert make_street_scene(0, time_of_day="dusk", lamps="off", n_pedestrians=0, n_cameras=1).lights == ()
    led = make_street_scene(0, time_of_day="noon", lamps="on", lamp="led", led_hz=250.0, n_pedestrians=0,
                            n_cameras=1)
    assert led.lights[0].waveform.shape == "pwm" and led.lights[0].waveform.freq_hz == 250.0


def test_options_reach_the_scene() -> None:
    values = parse_options({"scene": "street", "time": "night", "lamp": "fluorescent", "mains_hz": "60",
                            "led_duty": "0.25"}, "test")
    assert values["mains_hz"] == 60.0 and values["lamp"] == "fluorescent"
    with pytest.raises(ConfigError, match="mains_hz"):
        parse_options({"scene": "flicker", "mains_hz": "55"}, "test")
    with pytest.raises(ConfigError, match="lamps"):
        parse_options({"scene": "flicker", "lamps": "on"}, "test")  # the wall's one lamp is always on
    from rollcam.firmware.spec import CameraSpec, scene_of

    spec = CameraSpec.from_options("imx219", {"scene": "flicker", "lamp": "led", "led_hz": "500", "size": "160x120"})
    wave = scene_of(spec).lights[0].waveform
    assert (wave.shape, wave.freq_hz) == ("pwm", 500.0)


def _small_street(**options):
    scene = make_street_scene(2, time_of_day="night", n_pedestrians=12, n_cameras=2, width=160, height=120,
                              speed="fast", **options)
    return scene


@pytest.mark.parametrize("ego", [None, "pan"])
def test_fast_path_equals_the_brute_force_reference_with_flicker_on(ego) -> None:
    from rollcam.sim.scenegen import ego_preset

    scene = _small_street(ego=None if ego is None else ego_preset(ego), lamp="led", led_hz=900.0)
    r = Renderer(scene, 0, gain=6.0, light_window_ns=1_500_000)
    assert isinstance(r, FlickerRenderer)
    times = 5_000_000 + np.arange(120, dtype=np.int64) * 40_000
    fast = r.render_lines(times)
    ref = r.reference_lines(times)
    diff = np.abs(fast.image.astype(np.int16) - ref.image.astype(np.int16))
    assert diff.max() <= 1, diff.max()
    col = fast.image[:, :, 1].astype(np.float64).mean(axis=1)
    assert col.std() > 0  # the lamps band the picture (the test is not of a flat frame)
    for name in ("left", "right"):
        np.testing.assert_array_equal(getattr(fast.truth, name), getattr(ref.truth, name))


def test_frames_are_deterministic_and_walkers_are_lit_by_the_lamps() -> None:
    scene = _small_street()
    cam = SyntheticCamera(SENSOR, scene, size=(160, 120), exposure_ns=2_000_000, pixel_format="RG10",
                          noise=frozenset())
    a, b = cam.frame(3).data, SyntheticCamera(SENSOR, scene, size=(160, 120), exposure_ns=2_000_000,
                                              pixel_format="RG10", noise=frozenset()).frame(3).data
    np.testing.assert_array_equal(a, b)
    assert cam.frame(3).meta["lights"][0].startswith("street lamps: rectified 100 Hz")
    dark = make_street_scene(2, time_of_day="night", lamps="off", n_pedestrians=12, n_cameras=2, width=160,
                             height=120, speed="fast")
    assert cam.frame(3).data.mean() > SyntheticCamera(SENSOR, dark, size=(160, 120), exposure_ns=2_000_000,
                                                      pixel_format="RG10", noise=frozenset()).frame(3).data.mean()


def test_what_modulated_lights_do_not_take() -> None:
    chart = make_chart_scene(0, width=64, height=48)
    import dataclasses

    lit = dataclasses.replace(chart, lights=make_scene("flicker", width=64, height=48).lights)
    with pytest.raises(ConfigError, match="chart"):
        Renderer(lit)
    r = Renderer(make_scene("flicker", width=64, height=48))
    buf = np.empty((48, 64, 3), np.float32)
    with pytest.raises(ConfigError, match="integrate"):
        r.render_linear(np.zeros(48, np.int64), out=buf, hits=np.zeros(48, np.int64))
    assert type(Renderer(make_scene("flat", width=64, height=48))) is Renderer  # no lights: no extra work


def test_column_readout_bands_run_across_the_frame() -> None:
    """Read by columns, the windows slide along x: the bands are columns, period 1 / (f * line_time) columns."""
    scene = make_scene("flicker", 0, width=480, height=320, lamp="led", led_hz=400.0, led_duty=0.5)
    cam = SyntheticCamera(SENSOR, scene, size=(480, 320), readout="lr", exposure_ns=300_000)
    lin = cam.renderer.render_lines(cam.line_times_ns(0), by_column=True, linear=True).linear
    assert lin.shape[:2] == (320, 480)
    cols = lin[:, :, 1].astype(np.float64).mean(axis=0)
    rows = lin[:, :, 1].astype(np.float64).mean(axis=1)
    assert rows.max() - rows.min() < 1e-6 * rows.mean() < cols.max() - cols.min()
    want = 1e9 / (400.0 * cam.settings.timing.line_time_ns)
    assert abs(_period_rows(cols) - want) <= 1.0
    ref = cam.renderer.reference_lines(cam.line_times_ns(0), by_column=True).image
    fast = cam.renderer.render_lines(cam.line_times_ns(0), by_column=True).image
    assert np.abs(fast.astype(np.int16) - ref.astype(np.int16)).max() <= 1
