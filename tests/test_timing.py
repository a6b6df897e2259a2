"""Integer-ns timing: closed-form line and frame times, exact after 30 days of uptime."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from rollcam.common.errors import ConfigError
from rollcam.sim.hwconfig import load_sensor
from rollcam.sim.scenegen import make_chart_scene
from rollcam.sim.synthetic import SyntheticCamera, resolve_settings
from rollcam.sim.timing import LineTiming, Readout, line_sample_times_ns

IMX219 = LineTiming(182_400_000, 3448, 1763)
THIRTY_DAYS_NS = 30 * 86_400 * 10**9


def test_imx219_line_and_frame_time():
    assert IMX219.line_time_ns == 18904  # 18,903.5 ns rounded
    assert IMX219.fps == pytest.approx(30.0058, abs=1e-4)
    assert IMX219.line_offset_ns(1080) == 1080 * 3448 * 10**9 // 182_400_000


@given(frame=st.integers(0, 80_000_000), line=st.integers(0, 1079))
def test_row_times_after_30_days_match_closed_form(frame, line):
    start = IMX219.frame_start_ns(frame)
    times = line_sample_times_ns(start, 1080, IMX219, "top_to_bottom")
    expected = (frame * 1763 * 3448 + line * 3448) * 10**9 // 182_400_000
    # Floors of a sum and of its parts differ by at most 1 ns; both are exact integers, never drifting.
    assert expected - 1 <= int(times[line]) <= expected
    assert int(times[line]) == start + line * 3448 * 10**9 // 182_400_000


def test_frame_start_exact_at_30_days():
    n = THIRTY_DAYS_NS // IMX219.frame_period_ns
    assert IMX219.frame_start_ns(n) == n * 1763 * 3448 * 10**9 // 182_400_000
    assert IMX219.frame_start_ns(n) > THIRTY_DAYS_NS - 10**9


def test_readout_directions():
    t = line_sample_times_ns(100, 4, IMX219, "bottom_to_top")
    assert t[-1] == 100 and np.all(np.diff(t) < 0)
    assert Readout.parse("lr").by_column and Readout.parse("rl").reversed
    with pytest.raises(ConfigError, match="readout"):
        Readout.parse("diagonal")
    np.testing.assert_array_equal(line_sample_times_ns(7, 3, None), [7, 7, 7])


def test_bad_timing_rejected():
    with pytest.raises(ConfigError):
        LineTiming(0, 3448, 1763)


def test_synthetic_camera_pairs_and_clamped_exposure():
    sensor = load_sensor("letsroll")
    scene = make_chart_scene(0, vx_px_s=1000, width=192, height=108)
    cam = SyntheticCamera(sensor, scene, size=(192, 108), start_ns=THIRTY_DAYS_NS)
    gs, rs = cam.frame(5, "global"), cam.frame(5, "rolling")
    assert gs.timestamp_ns == rs.timestamp_ns == cam.settings.timing.frame_start_ns(5, THIRTY_DAYS_NS)
    assert gs.line_time_ns == 0 and rs.line_time_ns > 0
    assert [o.box_gs for o in gs.objects] == [o.box_gs for o in rs.objects]
    assert rs.row_times_ns[0] == gs.row_times_ns[0]
    s = resolve_settings(sensor, exposure_ns=10**10)  # 10 s: longer than the frame
    assert s.clamped_exposure and s.exposure_ns <= s.timing.frame_period_ns


@pytest.mark.parametrize("kwargs", [
    {"size": (3000, 3000)},  # rescaled clock: products that overflowed int64 before
    {"readout": "left_to_right"},  # column readout of a sensor timed by rows
    {"size": (160, 1)},
    {"size": (3, 2)},
    {"size": (960, 540)},
    {"fps": 10.0},
])
def test_rescaled_readouts_keep_frame_period_and_fit_the_frame(kwargs):
    sensor = load_sensor("imx219")
    s = resolve_settings(sensor, **kwargs)
    times = line_sample_times_ns(0, s.n_lines, s.timing, s.readout)
    assert np.all(np.diff(times) >= 0) and times[0] == 0
    assert times[-1] < s.timing.frame_period_ns  # every line is read within one frame period
    assert s.exposure_ns <= s.timing.frame_period_ns
    if "fps" not in kwargs:
        assert s.timing.frame_period_ns == IMX219.frame_period_ns  # exactly the sensor's frame rate
    # The whole readout takes the mode's readout time, whatever the output's line count.
    if "fps" not in kwargs and s.n_lines > 1:
        full = IMX219.line_offset_ns(1080)
        assert abs(int(s.timing.line_offset_ns(s.n_lines)) - full) <= 2


def test_line_offsets_never_overflow():
    timing = LineTiming(547_200_000_000, 3_723_840, 4898)
    offs = timing.line_offset_ns(np.arange(0, 100_000, 997))
    assert np.all(np.diff(offs) > 0)
    assert int(offs[-1]) == int(np.arange(0, 100_000, 997)[-1]) * 3_723_840 * 10**9 // 547_200_000_000
