"""``SyntheticProducer``: the FrameProducer the UVC function streams from, over a SyntheticCamera."""

from __future__ import annotations

import pytest
from rollcam.common.errors import DeviceError
from rollcam.emu.uvc import FrameProducer, SyntheticProducer
from rollcam.sim.hwconfig import load_sensor
from rollcam.sim.scenegen import make_scene
from rollcam.sim.synthetic import resolve_settings
from uvc_fakes import FakeProducer, ManualClock


@pytest.fixture
def producer():
    clock = ManualClock(5_000)
    sensor = load_sensor("imx219")
    return SyntheticProducer(sensor, make_scene("chart", 0, width=160, height=120), sizes=[(160, 120), (80, 60)],
                             clock=clock), clock


def test_protocol_conformance():
    assert isinstance(FakeProducer(), FrameProducer)
    sensor = load_sensor("imx219")
    assert isinstance(SyntheticProducer(sensor, make_scene("flat", 0, width=64, height=48), sizes=[(64, 48)]),
                      FrameProducer)


def test_sizes_intervals_and_configure(producer):
    p, clock = producer
    assert p.sizes() == [(160, 120), (80, 60)]
    ivs = p.intervals_ns(160, 120)
    native = resolve_settings(p.sensor, size=(160, 120)).timing.frame_period_ns
    assert ivs[0] == native and ivs[1:] == sorted(ivs[1:]) and len(set(ivs)) == len(ivs)
    clock.t_ns = 1_000_000
    slow = max(ivs)
    p.configure(80, 60, slow)
    f0, f1 = p.frame(0), p.frame(1)
    assert f0.data.shape == (60, 80, 3)
    assert f0.timestamp_ns == p.now_ns() == 1_000_000 - 5_000  # the device clock counts from creation; frame 0 now
    assert f1.timestamp_ns - f0.timestamp_ns in (slow, slow + 1)
    assert p.frame_due_ns(0) > f0.timestamp_ns + f0.exposure_ns
    with pytest.raises(DeviceError):
        p.configure(1920, 1080, slow)


def test_controls_clamp_and_keep_the_timeline(producer):
    p, _ = producer
    r = p.control_range("exposure_ns")
    assert r.minimum < r.default < r.maximum and r.step > 0
    t_before = p.frame(3).timestamp_ns
    assert p.set_control("exposure_ns", 10**12) == r.maximum
    assert p.frame(3).exposure_ns == r.maximum and p.frame(3).timestamp_ns == t_before
    assert p.set_control("gain", 0) == p.control_range("gain").minimum
    with pytest.raises(DeviceError):
        p.get_control("focus")
