"""Numerical stress tests at the extremes (docs/stress-tests.md lists every case and what it guarantees).

Each case asserts no crash, no NaN or inf, and correct integer-ns timing. Property-based cases draw their
inputs with hypothesis; explicit extremes pin the corners.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rollcam.common.errors import ConfigError
from rollcam.sim.codecs import codec
from rollcam.sim.exposure import integrate, plan_samples
from rollcam.sim.formats import FORMATS
from rollcam.sim.hwconfig import load_sensor
from rollcam.sim.noise import SensorModel
from rollcam.sim.scenegen import make_chart_scene, make_street_scene
from rollcam.sim.synthetic import SyntheticCamera, resolve_settings
from rollcam.sim.timing import NS_PER_S, LineTiming

DAY_NS = 86_400 * NS_PER_S
THIRTY_DAYS_NS = 30 * DAY_NS
IMX219 = load_sensor("imx219")
FAST = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def closed_form_rows(timing: LineTiming, start_ns: int, index: int, exposure_ns: int, n: int) -> list[int]:
    """Row sample times in Python integers: frame start + mid-exposure + floor(k * L * 1e9 / P)."""
    t0 = start_ns + index * timing.frame_period_pck * NS_PER_S // timing.pixel_rate_hz + exposure_ns // 2
    return [t0 + k * timing.line_length_pck * NS_PER_S // timing.pixel_rate_hz for k in range(n)]


def finite(a: np.ndarray | None) -> bool:
    return a is not None and bool(np.all(np.isfinite(a)))


# ----------------------------------------------------------------------------------- timing after 30 days
@FAST
@given(start_ns=st.integers(0, THIRTY_DAYS_NS), uptime_ns=st.integers(0, THIRTY_DAYS_NS))
def test_row_times_after_30_days_match_the_closed_form(start_ns, uptime_ns):
    cam = SyntheticCamera(IMX219, make_street_scene(0, width=64, height=48), size=(64, 48), start_ns=start_ns)
    t = cam.settings.timing
    index = uptime_ns * t.pixel_rate_hz // (t.frame_period_pck * NS_PER_S)
    rows = cam.line_times_ns(index)
    assert rows.dtype == np.int64
    assert rows.tolist() == closed_form_rows(t, start_ns, index, cam.settings.exposure_ns, 48)


def test_frames_render_after_30_days_of_uptime():
    cam = SyntheticCamera(IMX219, make_street_scene(0, speed="fast", width=64, height=48), size=(64, 48),
                          start_ns=THIRTY_DAYS_NS, pixel_format="RG10")
    index = 77_760_000  # 30 days at 30 fps
    f = cam.frame(index)
    assert f.timestamp_ns == cam.settings.timing.frame_start_ns(index, THIRTY_DAYS_NS) > 2 * THIRTY_DAYS_NS - DAY_NS
    assert f.data.max() <= 1023 and f.meta["blur_samples_max"] >= 1
    assert f.row_times_ns.tolist() == closed_form_rows(cam.settings.timing, THIRTY_DAYS_NS, index,
                                                       cam.settings.exposure_ns, 48)


# ----------------------------------------------------------------------------------- line times 1 ns .. 1 ms
@FAST
@given(line_ns=st.integers(1, 1_000_000), extra_pck=st.integers(0, 999), n_lines=st.integers(1, 8192),
       index=st.integers(0, 10**12))
def test_line_offsets_exact_for_line_times_1ns_to_1ms(line_ns, extra_pck, n_lines, index):
    # Counting the line in picoseconds (a 1e12 Hz clock) gives line times of line_ns + extra/1000 ns: whole
    # and fractional ns alike, as real pixel clocks give (imx219: 18,903.5 ns).
    timing = LineTiming(1_000_000_000_000, line_ns * 1000 + extra_pck, n_lines + 1)
    k = np.unique(np.array([0, min(1, n_lines - 1), n_lines // 2, n_lines - 1], np.int64))
    got = timing.line_offset_ns(k)
    want = [int(x) * timing.line_length_pck * NS_PER_S // timing.pixel_rate_hz for x in k]
    assert got.tolist() == want and np.all(np.diff(got) >= 0)
    assert timing.frame_start_ns(index) == index * timing.frame_period_pck * NS_PER_S // timing.pixel_rate_hz


# ----------------------------------------------------------------------------------- sensor sizes 1 row .. 8K
@pytest.mark.parametrize("size", [(1, 1), (64, 1), (1, 48), (7680, 2)])
def test_tiny_and_wide_sensors_render_through_the_sensor_path(size):
    cam = SyntheticCamera(IMX219, make_street_scene(0, speed="fast", width=size[0], height=size[1]), size=size,
                          pixel_format="RG10")
    f = cam.frame(3)
    assert f.data.shape == (size[1], size[0]) and f.data.dtype == np.uint16
    assert f.row_times_ns.shape == (size[1],) and np.all(np.diff(f.row_times_ns) > 0)


def test_8k_sensor_timing_and_sensor_model():
    s = resolve_settings(IMX219, size=(7680, 4320))
    rows = s.timing.line_offset_ns(np.arange(4320))
    assert rows[-1] == 4319 * s.timing.line_length_pck * NS_PER_S // s.timing.pixel_rate_hz
    assert rows[-1] < s.timing.frame_period_ns  # the whole readout fits the frame
    m = SensorModel(IMX219.noise, 10, "RGGB")
    dn = m.expose(np.full((4, 7680, 3), 0.4, np.float32), s.exposure_ns, 0, origin=(4316, 0), array_width=7680)
    assert dn.shape == (4, 7680) and 64 < dn.mean() < 1023


@pytest.mark.slow
def test_8k_frame_renders_through_the_sensor_path():
    cam = SyntheticCamera(IMX219, make_street_scene(0, speed="fast", width=7680, height=4320), size=(7680, 4320),
                          pixel_format="pRAA", blur_px=None)
    f = cam.frame(0)
    assert f.data.shape == (4320, 9600) and f.width == 7680


# ----------------------------------------------------------------------------------- exposure clamping
@FAST
@given(exposure_ns=st.integers(0, 10**15), fps=st.sampled_from([None, 1.0, 15.0, 30.0]))
def test_exposure_clamped_to_the_frame_as_the_sensor_does(exposure_ns, fps):
    s = resolve_settings(IMX219, size=(64, 48), exposure_ns=exposure_ns, fps=fps)
    t = s.timing
    line = t.line_offset_ns(1)
    max_lines = t.frame_period_pck // t.line_length_pck - IMX219.exposure.max_margin_lines
    assert isinstance(s.exposure_ns, int) and 0 < s.exposure_ns <= t.line_offset_ns(max_lines)
    assert s.exposure_ns < t.frame_period_ns
    in_range = IMX219.exposure.min_lines <= round(exposure_ns / line) <= max_lines
    assert s.clamped_exposure == (not in_range)


# ----------------------------------------------------------------------------------- objects near and behind
def _walker_scene(speed_mps: float, height_m: float = 1.7, size: tuple[int, int] = (96, 64)):
    """A street whose only walker walks straight through the camera (lane on the camera's position)."""
    scene = make_street_scene(0, width=size[0], height=size[1])
    cam = scene.cameras[0]
    cx, cy, _ = cam.position_m
    walker = dataclasses.replace(scene.pedestrians[0], lane_x_m=cx, lane_y_center_m=cy, lane_half_length_m=6.0,
                                 start_offset_m=0.0, speed_mps=speed_mps, height_m=height_m, direction=1)
    return dataclasses.replace(scene, pedestrians=(walker,))


@FAST
@given(frame=st.integers(0, 200), speed=st.sampled_from([1.0, 3.0, 30.0]))
def test_objects_crossing_the_camera_plane_or_behind_it(frame, speed):
    cam = SyntheticCamera(IMX219, _walker_scene(speed), size=(96, 64), pixel_format="RG10", blur_px=2.0)
    f = cam.frame(frame)
    assert f.data.dtype == np.uint16 and f.data.max() <= 1023
    for o in f.objects or ():
        for box in (o.box_gs, o.box_rs):
            assert box is None or all(math.isfinite(v) for v in box)


@pytest.mark.parametrize("speed_mps", [100.0, 1000.0])
def test_speeds_up_to_1000_mps_cap_the_samples_and_stay_finite(speed_mps):
    cam = SyntheticCamera(IMX219, _walker_scene(speed_mps), size=(96, 64), pixel_format="RG10")
    s = cam.settings
    plan = plan_samples(cam.renderer, cam.line_times_ns(0) - s.exposure_ns // 2, s.exposure_ns)
    assert plan.n.min() >= 1 and plan.n.max() <= 512 and np.all(np.isfinite(plan.speed_px_s))
    f = cam.frame(0)
    assert f.data.max() <= 1023


def test_1000_mps_chart_blur_is_finite_and_capped():
    vx = 1000.0 * 1000  # 1000 m/s at 1000 px/m
    scene = make_chart_scene(0, vx_px_s=vx, width=64, height=8)
    cam = SyntheticCamera(load_sensor("letsroll"), scene, size=(64, 8))
    s = cam.settings
    plan = plan_samples(cam.renderer, cam.line_times_ns(0) - s.exposure_ns // 2, s.exposure_ns)
    assert plan.capped and plan.n.max() == 512
    assert finite(integrate(cam.renderer, plan).linear)


@pytest.mark.parametrize("fmt", ["RG10", "BGR3"])
def test_zero_size_objects(fmt):
    cam = SyntheticCamera(IMX219, _walker_scene(2.0, height_m=0.0), size=(96, 64), pixel_format=fmt)
    for i in (0, 40, 80):
        assert cam.frame(i).data.dtype == (np.uint16 if fmt == "RG10" else np.uint8)
    chart = make_chart_scene(0, bar_width_px=1e-9, width=64, height=8)  # a zero-width bar is refused up front
    c2 = SyntheticCamera(load_sensor("letsroll"), chart, size=(64, 8), pixel_format="RGGB")
    assert c2.frame(0).data.dtype == np.uint8
    with pytest.raises(ConfigError, match="bar_width"):
        make_chart_scene(0, bar_width_px=0.0)


# ----------------------------------------------------------------------------------- gains and bit depths
@pytest.mark.parametrize("gain", ["min", "max", 1e-6, 1e6])
def test_gains_at_their_limits(gain):
    g = IMX219.gain
    value = {"min": g.analog_min * g.digital_min, "max": g.analog_max * g.digital_max}.get(gain, gain)
    cam = SyntheticCamera(IMX219, make_street_scene(0, width=64, height=48), size=(64, 48), pixel_format="RG10",
                          gain=value)
    f = cam.frame(0)
    assert f.meta["gain_clamped"] == isinstance(gain, float)
    assert g.analog_min <= f.meta["analog_gain"] <= g.analog_max
    assert g.digital_min <= f.meta["digital_gain"] <= g.digital_max
    assert f.data.max() <= 1023


@FAST
@given(bits=st.integers(8, 16), level=st.floats(0.0, 50.0), gain=st.floats(0.01, 1000.0),
       exposure_ns=st.integers(0, 10**10))
def test_bit_depths_8_to_16_stay_in_range(bits, level, gain, exposure_ns):
    noise = dataclasses.replace(IMX219.noise, black_level_dn=min(IMX219.noise.black_level_dn, (1 << bits) - 2))
    m = SensorModel(noise, bits, "GRBG")
    dn = m.expose(np.full((4, 6, 3), level, np.float32), exposure_ns, 0, analog_gain=gain)
    assert dn.dtype == np.uint16 and int(dn.max()) <= (1 << bits) - 1
    for f in FORMATS.values():
        if f.cfa == "GRBG" and f.bits <= bits:
            coded = codec(f.fourcc).encode(dn, sample_bits=bits)
            back = codec(f.fourcc).decode(coded, 6, 4)
            assert np.array_equal(back, dn >> (bits - f.bits))


def test_16_bit_mono_sensor_end_to_end():
    base = load_sensor("ov9281")
    noise = dataclasses.replace(base.noise, system_gain_dn_per_e=base.noise.system_gain_dn_per_e * 64,
                                black_level_dn=base.noise.black_level_dn * 64)  # a 16-bit ADC over the same well
    s = dataclasses.replace(base, bit_depth=16, formats=("Y16 ", "GREY"), noise=noise)
    cam = SyntheticCamera(s, make_street_scene(0, width=64, height=40), size=(64, 40), pixel_format="Y16")
    f = cam.frame(0)
    assert f.format == "Y16 " and f.data.dtype == np.uint16 and f.data.max() > 1023
