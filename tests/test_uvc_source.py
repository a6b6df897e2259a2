"""``uvc:VID:PID`` sources: the emulated camera in process and over USB/IP, options, and clear errors."""

from __future__ import annotations

import time

import numpy as np
import pytest
from rollcam.emu.usbip import USBIPServer
from rollcam.emu.uvc import UVCFunction
from rollcam.emu.uvc.convert import decode, encode
from rollcam.host import DeviceError, DeviceNotFoundError, SourceError, open_camera
from uvc_fakes import FakeProducer

EMU = "uvc:1209:0001?backend=emu&sensor=imx219&size=160x120&scene=chart&frames=3"


def test_emulated_uvc_frames_carry_exact_device_timing():
    with open_camera(EMU) as src:
        frames = list(src)
        producer = src.function.producer
        info = src.info()
    assert len(frames) == 3 and [f.sequence for f in frames] == [0, 1, 2]
    assert info["format"] == "YUYV" and info["transfer"] == "iso" and info["frames_damaged"] == 0
    assert info["fps"] == pytest.approx(30, rel=0.01)  # the mode's own rate is the default interval
    for i, f in enumerate(frames):
        truth = producer.frame(i)
        assert f.timestamp_ns == truth.timestamp_ns  # PTS at 1 GHz: exact integer ns
        assert f.format == "BGR3" and f.data.shape == (120, 160, 3)
        assert np.array_equal(f.data, decode(encode(truth.data, "YUYV").tobytes(), "YUYV", 160, 120))
        assert f.shutter == "rolling" and f.line_time_ns == truth.line_time_ns
        assert f.exposure_ns == truth.exposure_ns
        assert np.array_equal(f.row_times_ns, truth.row_times_ns)


def test_options_select_format_transfer_and_controls():
    uri = EMU.replace("frames=3", "frames=2") + "&format=mjpeg&transfer=bulk&exposure_us=5000&gain=2&fps=15"
    with open_camera(uri) as src:
        frames = list(src)
        producer = src.function.producer
        assert src.info()["fps"] == pytest.approx(15, rel=0.01)
    assert len(frames) == 2 and frames[0].meta["wire_format"] == "MJPG"
    assert producer.get_control("gain") == 200
    assert abs(producer.get_control("exposure_ns") - 5_000_000) < 100_000
    assert frames[0].exposure_ns == producer.get_control("exposure_ns")
    with open_camera(EMU.replace("frames=3", "frames=1") + "&decode=0&format=nv12") as src:
        (raw,) = list(src)
    assert raw.format == "NV12" and raw.data.shape == (180, 160)


def test_uvc_source_over_usbip():
    fn = UVCFunction(FakeProducer(), transfer="iso")
    with USBIPServer([fn], port=0) as srv:
        host, port = srv.address
        with open_camera(f"uvc:1209:0001?backend=usbip&usbip={host}:{port}&busid=1-1&frames=2&size=32x24") as src:
            frames = list(src)
            assert src.info()["width"] == 32
        assert [f.timestamp_ns for f in frames] == [fn.producer.timestamp_ns(i) for i in range(2)]
        assert frames[0].shutter == "unknown" and frames[0].line_time_ns == 0  # no sensor= given
        deadline = time.monotonic() + 5
        while srv.exports["1-1"].owner is not None and time.monotonic() < deadline:
            time.sleep(0.01)  # the server notices the closed connection on its own thread
        with pytest.raises(DeviceNotFoundError, match="is 1209:0001"):
            open_camera(f"uvc:1209:9999?backend=usbip&usbip={host}:{port}")


@pytest.mark.parametrize(("uri", "match"), [
    ("uvc:xyz", "VID:PID"),
    ("uvc:1209:0001?backend=emu&colour=red", "unknown option"),
    ("uvc:1209:0001?backend=bogus", "backend"),
    ("uvc:1209:0001?scene=chart", "need backend=emu"),
    ("uvc:1209:0001?backend=emu&sensor=imx219&size=160x120&scene=chart&format=h264", "offers"),
    ("uvc:1209:0001?backend=emu&sensor=nosuch", "nosuch"),
])
def test_bad_uvc_uris_are_clear_errors(uri, match):
    with pytest.raises(SourceError, match=match):
        open_camera(uri)


def test_absent_usbip_server_is_a_missing_device():
    with pytest.raises(DeviceNotFoundError, match="USB/IP import failed"):
        open_camera("uvc:1209:0001?backend=usbip&usbip=127.0.0.1:1")


def test_real_libusb_without_a_camera_is_a_clear_error():
    with pytest.raises(DeviceError, match=r"libusb|no USB device"):
        open_camera("uvc:1209:0001?frames=1")


@pytest.mark.hardware
def test_real_uvc_camera():
    """Set ROLLCAM_UVC=VID:PID (hex) to stream from a real UVC camera through libusb."""
    import os

    ids = os.environ.get("ROLLCAM_UVC")
    if not ids:
        pytest.skip("no real UVC camera named in ROLLCAM_UVC")
    with open_camera(f"uvc:{ids}?frames=3") as src:
        frames = list(src)
    assert len(frames) == 3 and all(f.data.size for f in frames)
    assert frames[1].timestamp_ns > frames[0].timestamp_ns


def test_emulated_timestamps_are_the_full_device_clock_after_a_wrap():
    with open_camera(EMU.replace("frames=3", "frames=2")) as src:
        producer = src.function.producer
        producer.camera.boot_ns -= 5 * (1 << 32)  # the device has been up for ~21 s when streaming starts:
        producer.configure(160, 120, producer.camera.frame_interval_ns)  # its timeline starts now
        frames = list(src)
    assert frames[0].timestamp_ns > 5 * (1 << 32)
    assert [f.timestamp_ns for f in frames] == [producer.frame(i).timestamp_ns for i in range(2)]


def test_a_bad_option_found_while_negotiating_releases_the_camera(monkeypatch):
    closed = []
    original = UVCFunction.close
    monkeypatch.setattr(UVCFunction, "close", lambda self: (closed.append(self), original(self)))
    with pytest.raises(SourceError, match="h264"):
        open_camera("uvc:1209:0001?backend=emu&format=h264&scene=flat")
    assert len(closed) == 1
