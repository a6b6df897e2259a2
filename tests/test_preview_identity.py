"""One raw frame previews identically whatever carried it: in process (``emu:``), V4L2, HTTP MJPEG and UVC.

The emulated imx219 streams CSI-2 packed RAW10 (pRAA) of a flat field with the sensor's noise and black level.
A flat scene makes frame N the same whenever it is rendered, so every transport's frame N can be compared
with frame N rendered here. Raw-carrying paths must give the same samples and the same preview; HTTP and UVC
carry the device's preview itself, through the codec table's MJPG and YUYV rows, so what the host decodes must
equal that preview encoded and decoded by the same rows, byte for byte.
"""

from __future__ import annotations

import numpy as np
import pytest
from rollcam.emu.http.mjpeg import MjpegServer
from rollcam.emu.v4l2 import Device
from rollcam.emu.v4l2.driver import EmuDriver
from rollcam.firmware.camera import FirmwareCamera, FramePlan
from rollcam.host import open_camera
from rollcam.host.preview import frame_bgr
from rollcam.sim.codecs import Levels, codec
from rollcam.sim.frame import Frame
from rollcam.sim.hwconfig import load_sensor

SENSOR, FOURCC, (W, H) = "imx219", "pRAA", (640, 480)
SCENE = {"scene": "flat", "level": 0.3}
LEVELS = Levels.of_sensor(load_sensor(SENSOR))


def camera(**kw) -> FirmwareCamera:
    return FirmwareCamera(SENSOR, scene=dict(SCENE), size=(W, H), pixel_format=FOURCC, **kw)


def raw_frame(seq: int) -> Frame:
    """Frame ``seq`` of the firmware camera, rendered in process."""
    cam = camera(clock=lambda: 0)
    cam.stream_on()
    return cam.render(FramePlan(seq, cam.current_schedule()))


def carried(fourcc: str, picture: np.ndarray) -> np.ndarray:
    """``picture`` as it arrives through wire format ``fourcc`` of the codec table."""
    c = codec(fourcc)
    return c.decode(c.encode(picture), W, H)


@pytest.fixture(scope="module")
def frame0() -> tuple[Frame, np.ndarray]:
    ref = raw_frame(0)
    return ref, frame_bgr(ref)


def test_the_reference_preview_is_the_codec_tables_less_the_sensor_black_level(frame0):
    ref, want = frame0
    assert ref.format == FOURCC and LEVELS.black_level_dn > 0
    assert np.array_equal(want, codec(FOURCC).preview(ref.data, W, H, LEVELS))
    assert not np.array_equal(want, codec(FOURCC).preview(ref.data, W, H))  # the black level is subtracted
    assert want.shape == (H, W, 3) and want.dtype == np.uint8 and 40 < want.mean() < 220


def test_in_process_emu_source(frame0):
    ref, want = frame0
    with open_camera(f"emu:{SENSOR}?format={FOURCC}&scene=flat&level=0.3&size={W}x{H}&serial=0001") as src:
        f = src.read()
    assert f.format == FOURCC and f.data.tobytes() == ref.data.tobytes()
    assert np.array_equal(frame_bgr(f), want)


def test_v4l2_buffer(frame0):
    ref, want = frame0
    with Device(EmuDriver(camera(clock=lambda: 0), realtime=False)) as d:
        d.set_format(W, H, FOURCC)
        buf = next(d.stream(frames=1))
    assert buf.sequence == 0 and buf.fourcc == FOURCC and buf.data.tobytes() == ref.data.tobytes()
    assert np.array_equal(buf.image(), want)
    as_frame = Frame(data=buf.data, format=buf.fourcc, sequence=buf.sequence, timestamp_ns=buf.timestamp_ns,
                     line_time_ns=0, readout=ref.readout, exposure_ns=0, size=(W, H))
    assert np.array_equal(codec(FOURCC).preview(as_frame.data, W, H, LEVELS), want)


def test_http_mjpeg_stream():
    with MjpegServer(camera()) as srv, open_camera(srv.url + "#frames=1") as src:
        f = src.read()
    assert f.format == "BGR3"
    want = frame_bgr(raw_frame(f.sequence))  # the part's X-Sequence names the firmware frame
    assert np.array_equal(f.data, carried("MJPG", want))


@pytest.mark.parametrize(("wire", "decode"), [("yuyv", 1), ("mjpeg", 0)])
def test_uvc_over_usbip(frame0, wire, decode):
    pytest.importorskip("usb")
    from rollcam.emu.usbip import USBIPServer
    from rollcam.emu.uvc import FirmwareProducer, UVCFunction

    _, want = frame0
    function = UVCFunction(FirmwareProducer(camera()), transfer="bulk")
    with USBIPServer([function], port=0) as srv:
        host, port = srv.address[:2]
        uri = (f"uvc:1209:0001?backend=usbip&usbip={host}:{port}&busid=1-1&size={W}x{H}&format={wire}"
               f"&decode={decode}&frames=1")
        with open_camera(uri) as src:
            f = src.read()
    fourcc = {"yuyv": "YUYV", "mjpeg": "MJPG"}[wire]
    assert f.format == ("BGR3" if decode else fourcc)
    assert np.array_equal(frame_bgr(f), carried(fourcc, want))  # the device's frame 0, its preview on the wire
