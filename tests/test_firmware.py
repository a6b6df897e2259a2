"""Firmware camera: register map with the parts' effects, controls, scheduler, test patterns, flips."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import FakeClock
from rollcam.common.errors import ConfigError, DeviceError
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.patterns import render_pattern
from rollcam.firmware.scheduler import FrameSchedule
from rollcam.sim.hwconfig import list_sensors, load_sensor
from rollcam.sim.timing import NS_PER_S, LineTiming


def cam(sensor: str = "imx219", **kw) -> FirmwareCamera:
    return FirmwareCamera(sensor, scene={"scene": "flat"}, size=(640, 480) if sensor == "imx219" else None, **kw)


def test_imx219_register_map_uses_the_public_addresses():
    c = cam()
    assert c.read_register(0x0000) == 0x0219
    assert c.read_register("CHIP_ID") == 0x0219
    assert c.read_register(0x0100) == 0
    assert c.read_register(0x0160) == 1763  # FRM_LENGTH_A of the 640x480 mode
    assert c.read_register(0x0162) == 3448  # LINE_LENGTH_A
    assert c.read_register(0x0158) == 0x0100  # DIGITAL_GAIN 1.0
    assert c.read_register(0x0172) == 0 and c.read_register(0x0600) == 0
    with pytest.raises(DeviceError, match="read-only"):
        c.write_register(0x0000, 1)
    with pytest.raises(ConfigError, match="inside FRM_LENGTH_A"):
        c.read_register(0x0161)
    with pytest.raises(ConfigError, match="does not fit"):
        c.write_register(0x0157, 0x100)


def test_frame_length_sets_frame_rate_and_bounds_exposure():
    c = cam()
    c.write_register(0x015A, 1700)
    assert c.read_register(0x015A) == 1700
    c.write_register(0x0160, 1000)  # shorter frame: exposure clamps to frame length - 4
    assert c.read_register(0x015A) == 996
    assert c.frame_interval_ns == LineTiming(182_400_000, 3448, 1000).frame_period_ns
    assert c.controls()["exposure"]["max"] == 996
    c.write_register(0x015A, 5000)
    assert c.read_register(0x015A) == 996
    c.set_control("vblank", 3000 - 480)
    assert c.read_register(0x0160) == 3000
    assert c.controls()["exposure"]["max"] == 2996


def test_gain_codes_follow_the_sensor_formula():
    c = cam()
    c.write_register("ANALOG_GAIN", 128)  # 256 / (256 - 128) = 2x
    c.write_register("DIGITAL_GAIN", 0x0200)  # 2x
    assert c.state.gain == pytest.approx(4.0)
    assert c.set_control("analogue_gain", 10_000) == 232  # clamped to the part's maximum code


def test_mode_select_starts_and_stops_the_stream():
    c = cam()
    c.write_register(0x0100, 1)
    assert c.streaming and c.read_register(0x0100) == 1
    c.write_register(0x0100, 0)
    assert not c.streaming


def test_flips_change_bayer_order_and_are_refused_while_streaming():
    c = cam()
    assert c.state.bayer_order == "RGGB"
    c.write_register(0x0172, 0b01)
    assert c.state.bayer_order == "GRBG"
    c.set_control("vflip", 1)
    assert c.state.bayer_order == "BGGR" and c.read_register(0x0172) == 0b11
    c.stream_on()
    with pytest.raises(DeviceError, match="while streaming"):
        c.set_control("hflip", 0)
    with pytest.raises(DeviceError, match="while streaming"):
        c.write_register(0x0172, 0)
    c.set_control("hflip", 1)  # no change: allowed


def test_vflip_keeps_first_line_read_first_and_mirrors_the_image():
    clock = FakeClock(1_000_000_000)  # both streams start at the same device time, so the moving chart is in one place
    a = FirmwareCamera("imx219", scene={"scene": "chart"}, size=(640, 480), clock=clock)
    b = FirmwareCamera("imx219", scene={"scene": "chart"}, size=(640, 480), clock=clock)
    b.set_control("vflip", 1)
    b.set_control("hflip", 1)
    a.stream_on()
    b.stream_on()
    fa, fb = a.render(a.plan_next()), b.render(b.plan_next())
    assert np.all(np.diff(fb.row_times_ns) > 0)  # row 0 is still read first
    assert fb.meta["bayer_order"] == "BGGR"
    # The chart has vertical bars: vertical structure is row-time independent, so the mirror shows exactly.
    assert fb.objects and len(fb.objects) == len(fa.objects)
    xa = sorted(round(o.box_gs[0]) for o in fa.objects if o.box_gs)
    xb = sorted(round(640 - o.box_gs[2]) for o in fb.objects if o.box_gs)
    assert xa == xb


def test_test_pattern_replaces_the_scene():
    c = cam()
    c.stream_on()
    c.write_register(0x0600, 2)  # colour bars
    f = c.render(c.plan_next())
    assert np.array_equal(f.data, render_pattern("bars", 640, 480))
    assert f.objects == ()
    with pytest.raises(ConfigError, match="not a test pattern code"):
        c.write_register(0x0600, 0x77)
    c.write_register(0x0600, 0)
    assert not np.array_equal(c.render(c.plan_next()).data, f.data)


def test_every_sensor_builds_and_reads_its_registers():
    for name in list_sensors():
        c = FirmwareCamera(name, scene={"scene": "flat"})
        for r in load_sensor(name).registers:
            assert 0 <= c.read_register(r.address) < 1 << r.width_bits
        assert c.identity().startswith(f"rollcam,{name.upper()}-EMU,")


def test_shutter_switch_only_where_the_sensor_has_both():
    with pytest.raises(DeviceError, match="only a rolling shutter"):
        cam().set_shutter("global")
    c = FirmwareCamera("letsroll", scene={"scene": "flat"})
    c.set_shutter("global")
    c.stream_on()
    assert c.render(c.plan_next()).line_time_ns == 0


def test_scheduler_row_and_frame_due_times_are_exact_integers():
    t = LineTiming(182_400_000, 3448, 1763)
    s = FrameSchedule(t, 5_000, 10, 1_000_000, 1080)
    assert s.start_ns(10) == 5_000
    assert s.start_ns(11) == 5_000 + 1763 * 3448 * NS_PER_S // 182_400_000
    assert s.line_due_ns(10, 0) == 5_000 + 1_000_000 + 3448 * NS_PER_S // 182_400_000
    assert s.frame_due_ns(10) == s.line_due_ns(10, 1079)
    assert s.band_due_ns(10, 7, 8) == s.frame_due_ns(10)
    assert s.seq_started_by(4_999) == 9
    for seq in (10, 11, 500, 10**9):
        assert s.seq_started_by(s.start_ns(seq)) == seq
        assert s.seq_started_by(s.start_ns(seq) - 1) == seq - 1
    g = FrameSchedule(t, 0, 0, 1_000_000, 1080, rolling=False)
    assert g.line_start_ns(0, 500) == 0 and s.line_start_ns(10, 500) > s.start_ns(10)


def test_plan_skips_late_frames_and_timing_changes_apply_from_the_next_frame():
    clock = FakeClock(1_000_000_000)
    c = cam(clock=clock)
    c.stream_on()
    p0 = c.plan_next(c.clock_ns())
    assert p0.seq == 0 and p0.start_ns == c.clock_ns()
    c.set_control("vblank", 2000)
    p1 = c.plan_next()
    assert p1.start_ns == p0.schedule.start_ns(1)  # the running frame finishes on the old timing
    assert p1.schedule.timing.frame_length_lines == 2480
    clock.t += 10 * NS_PER_S
    p2 = c.plan_next(c.clock_ns())
    assert p2.seq > 2 and c.stats.skipped == p2.seq - 2
    assert p2.due_ns >= c.clock_ns()


def test_external_trigger_makes_one_frame_per_trigger():
    clock = FakeClock(1_000_000_000)
    c = cam(clock=clock)
    with pytest.raises(DeviceError, match="external"):
        c.trigger()
    c.set_trigger_mode("external")
    c.stream_on()
    assert c.plan_next() is None
    clock.t += 123_456
    t = c.trigger()
    p = c.plan_next()
    assert p.start_ns == t and c.plan_next() is None


def test_scene_controls_validate_and_apply():
    c = cam()
    c.set_options({"level": 0.9})
    with pytest.raises(ConfigError, match="does not apply"):
        c.set_options({"speed": "fast"})
    c.set_options({"scene": "street", "speed": "fast", "seed": 3})
    assert c.scene_options == {"seed": 3, "scene": "street", "speed": "fast"}


def test_patterns_are_deterministic():
    for name in ("bars", "fade_bars", "solid", "pn9", "walking_ones"):
        img = render_pattern(name, 64, 32)
        assert img.shape == (32, 64, 3) and img.dtype == np.uint8
    pn = render_pattern("pn9", 64, 32)
    assert 0.3 < (np.unpackbits(pn[..., 0]).mean()) < 0.7


def test_frame_interval_and_next_frame():
    c = cam()
    assert c.next_frame() is None  # idle
    interval = c.set_frame_interval_ns(50_000_000)
    assert abs(interval - 50_000_000) <= c.state.timing.line_time_ns
    c.stream_on()
    f0, f1 = c.next_frame(), c.next_frame()
    assert (f0.sequence, f1.sequence) == (0, 1)
    assert f1.timestamp_ns - f0.timestamp_ns == c.state.timing.frame_start_ns(1)


def test_every_door_refuses_a_shutter_the_sensor_lacks():
    # the serial SHUTTER command, serial OPT and an emu: URI agree: imx219 reads out rolling only
    from rollcam.firmware.protocol import handle_line
    from rollcam.firmware.spec import CameraSpec

    c = FirmwareCamera(CameraSpec.from_options("imx219", {"size": "320x240"}))
    assert handle_line(c, "SHUTTER GLOBAL").startswith("ERR")
    assert handle_line(c, "OPT shutter global").startswith("ERR")
    assert handle_line(c, "SHUTTER?") == "ROLLING"
    with pytest.raises(ConfigError, match="only a rolling shutter"):
        CameraSpec.from_options("imx219", {"shutter": "global"})
    assert CameraSpec.from_options("ov9281", {}).shutter == "global"
