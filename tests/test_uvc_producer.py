"""``FirmwareProducer``: the FrameProducer the UVC function streams from, over the one FirmwareCamera."""

from __future__ import annotations

import pytest
from helpers import FakeClock
from rollcam.common.errors import DeviceError
from rollcam.emu.uvc import FirmwareProducer, FrameProducer
from rollcam.firmware.camera import FirmwareCamera
from rollcam.sim.synthetic import resolve_settings
from uvc_fakes import FakeProducer


@pytest.fixture
def producer():
    clock = FakeClock(5_000)
    camera = FirmwareCamera("imx219", scene={"scene": "chart"}, size=(640, 480), clock=clock)
    return FirmwareProducer(camera), clock


def test_protocol_conformance(producer):
    assert isinstance(FakeProducer(), FrameProducer)
    assert isinstance(producer[0], FrameProducer)


def test_sizes_intervals_and_configure(producer):
    p, clock = producer
    sizes = p.sizes()
    assert sizes[0] == (640, 480) and sorted(sizes) == sorted(p.camera.sizes())  # the current size first
    ivs = p.intervals_ns(640, 480)
    native = resolve_settings(p.camera.sensor, size=(640, 480)).timing.frame_period_ns
    assert ivs[0] == native and ivs[1:] == sorted(ivs[1:]) and len(set(ivs)) == len(ivs)
    clock.t = 1_000_000
    slow = max(ivs)
    p.configure(640, 480, slow)
    f0, f1 = p.frame(0), p.frame(1)
    assert f0.data.shape == (480, 640, 3)
    assert f0.timestamp_ns == p.now_ns() == 1_000_000 - 5_000  # the device clock counts from boot; frame 0 now
    assert abs(f1.timestamp_ns - f0.timestamp_ns - slow) <= p.camera.spec.settings.timing.line_time_ns
    assert p.frame_due_ns(0) > f0.timestamp_ns + f0.exposure_ns
    # A size the camera has no mode for is refused as the UVC function expects (DeviceError -> a stall),
    # and the programming in effect stays.
    with pytest.raises(DeviceError, match="123x45"):
        p.configure(123, 45, slow)
    assert p.camera.size == (640, 480) and p.camera.streaming


def test_controls_clamp_and_keep_the_timeline(producer):
    p, _ = producer
    p.configure(640, 480, p.intervals_ns(640, 480)[0])
    r = p.control_range("exposure_ns")
    assert r.minimum < r.default < r.maximum and r.step > 0
    t_before = p.frame(3).timestamp_ns
    assert p.set_control("exposure_ns", 10**12) == r.maximum
    assert p.frame(3).exposure_ns == r.maximum and p.frame(3).timestamp_ns == t_before
    assert p.set_control("gain", 0) == p.control_range("gain").minimum
    with pytest.raises(DeviceError):
        p.get_control("focus")
