"""Raw sensor formats through the emulated devices: V4L2 formats and buffers, flips, serial FMT, HTTP preview."""

from __future__ import annotations

import dataclasses
import errno
import urllib.request

import cv2
import numpy as np
import pytest
from helpers import FakeClock
from rollcam.common.errors import ConfigError, DeviceError
from rollcam.emu.http.mjpeg import MjpegServer
from rollcam.emu.v4l2 import Device, V4L2Error, raw
from rollcam.emu.v4l2 import functions as fn
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.protocol import handle_line
from rollcam.sim import formats as sf


def dev(sensor: str = "imx219", size: tuple[int, int] = (640, 480), **kw) -> Device:
    kw.setdefault("realtime", False)
    return Device.open(sensor, scene=kw.pop("scene", {"scene": "street"}), size=size, **kw)


def test_enum_fmt_lists_the_sensor_raw_formats_with_kernel_sizes():
    with dev() as d:
        descs = {f.pixelformat: f for f in fn.enum_formats(d.driver)}
        assert {"YUYV", "MJPG", "RG10", "pRAA", "RGGB"} <= set(descs)
        assert descs["pRAA"].description == "10-bit Bayer RGRG/GBGB Packed" and not descs["pRAA"].flags
        for fourcc, bpl in (("RG10", 640 * 2), ("pRAA", 640 * 10 // 8), ("RGGB", 640)):
            f = fn.try_format(d.driver, 640, 480, fourcc)
            assert (f.pixelformat, f.bytesperline, f.sizeimage) == (fourcc, bpl, bpl * 480)
            assert f.colorspace == raw.Colorspace.RAW
        assert [(s.width, s.height) for s in fn.enum_frame_sizes(d.driver, "pRAA")] == d.driver.camera.sizes()
        assert fn.try_format(d.driver, 640, 480, "pRCC").pixelformat == "YUYV"  # 12-bit: not this sensor's
    with dev("imx477", size=(1332, 990)) as d:
        f = fn.set_format(d.driver, 1332, 990, "pRCC")
        assert (f.bytesperline, f.sizeimage) == (1998, 1998 * 990)  # 3 bytes per 2 pixels


@pytest.mark.parametrize("realtime", [False, True])
@pytest.mark.parametrize("fourcc", ["RG10", "pRAA"])
def test_raw_buffers_decode_to_noisy_10_bit_samples(fourcc, realtime):
    with dev(realtime=realtime, scene={"scene": "flat"}) as d:
        fmt = d.set_format(640, 480, fourcc)
        bufs = list(d.stream(buffers=3, frames=2))
    assert [b.fourcc for b in bufs] == [fourcc, fourcc] and all(b.bytesused == fmt.sizeimage for b in bufs)
    def unpacked(x):  # the kernel's layouts, read without the codec table
        return x.data.view(np.uint16).reshape(480, 640) if fourcc == "RG10" else \
            sf.unpack_csi2(x.data.reshape(480, -1), 10, 640)

    a, b = (unpacked(x) for x in bufs)
    assert a.shape == (480, 640) and a.dtype == np.uint16 and a.max() < 1024
    assert np.array_equal(a, bufs[0].samples())
    # A flat scene still varies: shot/read noise within a frame, and temporal noise from frame to frame.
    assert a.std() > 1 and not np.array_equal(a, b)
    assert bufs[0].image().shape == (480, 640, 3)


def test_raw_buffer_previews_subtract_the_sensor_black_level():
    with dev(scene={"scene": "flat", "level": 0.0}) as d:  # a dark frame: samples sit at the black level
        d.set_format(640, 480, "RG10")
        (buf,) = list(d.stream(frames=1))
    black = d.driver.camera.sensor.noise.black_level_dn
    assert buf.levels is not None and buf.levels.black_level_dn == black > 0
    assert abs(float(np.median(buf.samples())) - black) <= 2
    assert float(np.median(buf.image())) <= 40  # black previews (near) black
    assert float(np.median(dataclasses.replace(buf, levels=None).image())) > 60  # 64 DN of 1023 is grey


def test_fixed_pattern_noise_follows_the_serial_number():
    def dark_frame(serial: str) -> np.ndarray:
        cam = FirmwareCamera("imx219", scene={"scene": "flat"}, size=(640, 480), pixel_format="RG10",
                             serial_number=serial)
        cam.stream_on()
        return np.mean([cam.next_frame().data.astype(float) for _ in range(2)], axis=0)

    a, a2, b = dark_frame("0001"), dark_frame("0001"), dark_frame("0002")
    assert np.array_equal(a, a2) and not np.array_equal(a, b)


def test_flip_changes_the_fourcc_and_is_refused_while_streaming():
    with dev() as d:
        d.set_format(640, 480, "RG10")
        d.controls["hflip"].value = 1
        assert fn.get_format(d.driver).pixelformat == "BA10"  # GRBG order, as Linux's imx219 reports
        d.controls["vflip"].value = 1
        assert fn.get_format(d.driver).pixelformat == "BG10"
        assert "BG10" in [f.pixelformat for f in fn.enum_formats(d.driver)]
        assert fn.try_format(d.driver, 640, 480, "RG10").pixelformat == "BG10"  # either order's name maps
        stream = d.stream(frames=None)
        buf = next(stream)
        assert buf.fourcc == "BG10"
        with pytest.raises(V4L2Error) as info:
            d.controls["hflip"].value = 0
        assert info.value.errno == errno.EBUSY
        stream.close()
        d.controls["hflip"].value = 0
        assert fn.get_format(d.driver).pixelformat == "GB10"


def test_flipped_raw_is_the_unflipped_raw_mirrored():
    frozen = {"scene": {"scene": "chart"}, "clock": lambda: 0}  # both frames at the same scene time
    with dev(**frozen) as plain, dev(**frozen) as flipped:
        for x in (plain, flipped):
            x.set_format(640, 480, "RG10")
        flipped.controls["hflip"].value = 1
        p, f = next(plain.stream(frames=1)), next(flipped.stream(frames=1))
        assert p.fourcc == "RG10" and f.fourcc == "BA10"
        # The same array read right to left: pixels, fixed-pattern and temporal noise all mirrored.
        assert np.array_equal(f.samples(), p.samples()[:, ::-1])
        for x in (plain, flipped):
            x.controls["test_pattern"].value = 1  # bars, mosaicked in the output's Bayer order
        for buf in (next(plain.stream(frames=1)), next(flipped.stream(frames=1))):
            bars = buf.image()
            assert tuple(bars[10, 10]) == (255, 255, 255) and tuple(bars[10, 630]) == (0, 0, 0)
            assert tuple(bars[10, 120] > 200) == (False, True, True)  # yellow (BGR)


def test_format_change_while_streaming_is_ebusy():
    with dev() as d:
        d.set_format(640, 480, "RG10")
        stream = d.stream(frames=None)
        next(stream)
        for fourcc in ("pRAA", "YUYV"):
            with pytest.raises(V4L2Error) as info:
                fn.set_format(d.driver, 640, 480, fourcc)
            assert info.value.errno == errno.EBUSY
        with pytest.raises(DeviceError):
            d.driver.camera.set_format("pRAA")  # the firmware refuses too (serial, UVC paths)
        stream.close()
        assert fn.set_format(d.driver, 640, 480, "pRAA").pixelformat == "pRAA"


def test_camera_format_state_and_errors():
    cam = FirmwareCamera("ov9281", scene={"scene": "flat"})
    assert cam.formats[-2:] == ["Y10 ", "Y10P"] and cam.pixel_format == "BGR3"  # the spec's default
    assert cam.set_format("Y10") == "Y10 "
    with pytest.raises(ConfigError, match="RG10"):
        cam.set_format("RG10")
    with pytest.raises(ConfigError, match="blur_px"):
        FirmwareCamera("imx219", blur_px=-1)


def test_blur_option_integrates_raw_frames_over_the_exposure():
    cam = FirmwareCamera("imx219", scene={"scene": "street"}, size=(640, 480), pixel_format="RG10", blur_px=0)
    cam.stream_on()
    assert cam.next_frame().meta["blur_samples_max"] == 1
    cam.update(blur_px=0.5)
    assert cam.spec.blur_px == 0.5 and "blur_bound_px" in cam.next_frame().meta


def test_serial_fmt_commands():
    cam = FirmwareCamera("imx219", scene={"scene": "flat"}, size=(640, 480))
    assert handle_line(cam, "FMT?") == "BGR3"  # the spec's default format
    assert handle_line(cam, "FMT rg10") == "OK RG10"
    assert handle_line(cam, "CTRL hflip 1") == "OK 1"
    assert handle_line(cam, "FMT?") == "BA10"
    assert handle_line(cam, "FMTS?").split()[-3:] == ["pgAA", "BA10", "GRBG"]
    assert handle_line(cam, "STREAM ON") == "OK"
    assert handle_line(cam, "FMT pgAA").startswith("ERR 103")
    assert handle_line(cam, "STREAM OFF") == "OK"
    assert handle_line(cam, "FMT RG12").startswith("ERR 102")
    assert handle_line(cam, "FMT pgaa") == "OK pgAA"
    assert handle_line(cam, "REG ORIENTATION 2") == "OK 0x0002"  # the register flips as the controls do
    assert handle_line(cam, "FMT?") == "pGAA"


def test_http_serves_a_preview_of_a_raw_stream():
    cam = FirmwareCamera("imx219", scene={"scene": "flat"}, size=(640, 480), pixel_format="pRAA")
    with MjpegServer(cam) as srv, urllib.request.urlopen(srv.url.replace("stream.mjpg", "snapshot.jpg"),
                                                            timeout=10) as r:
        img = cv2.imdecode(np.frombuffer(r.read(), np.uint8), cv2.IMREAD_COLOR)
    assert img.shape == (480, 640, 3) and 20 < img.mean() < 235


def test_streamon_refuses_buffers_too_small_for_a_format_changed_elsewhere():
    with dev() as d:
        d.set_format(640, 480, "RGGB")  # 1 byte per pixel
        fn.request_buffers(d.driver, 2)
        assert handle_line(d.driver.camera, "FMT RG10") == "OK RG10"  # over the serial line: 2 bytes per pixel
        with pytest.raises(V4L2Error) as info:
            fn.stream_on(d.driver)
        assert info.value.errno == errno.EINVAL
        fn.request_buffers(d.driver, 0)
        assert next(d.stream(frames=1)).fourcc == "RG10"


# ------------------------------------------------------------------------------------- compiled before the clock
def test_stream_on_renders_a_new_kind_of_frame_before_the_clock_starts(monkeypatch):
    from rollcam.firmware import imaging

    monkeypatch.setattr(imaging, "_WARM_KINDS", set())  # as in a fresh process
    clock = FakeClock()  # the warm-up render moves it on by 20 s, as a cold numba cache would
    cam = FirmwareCamera("imx219", scene={"scene": "flat"}, size=(640, 480), pixel_format="RG10", hflip=True,
                         clock=clock)
    render = cam.imager.render
    warmed = []

    def slow_render(spec, seq, start_ns, shutter=None):
        clock.t += 20 * 10**9
        warmed.append(seq)
        return render(spec, seq, start_ns, shutter)

    monkeypatch.setattr(cam.imager, "render", slow_render)
    cam.stream_on()
    assert warmed == [0] and imaging.kernel_kind(cam.spec) in imaging._WARM_KINDS
    # The stream starts after the warm-up: its first frame is due a frame from now, not 20 s ago (skipped).
    plan = cam.plan_next(now_ns=cam.clock_ns())
    assert plan.seq == 0 and plan.start_ns == cam.clock_ns() and cam.stats.skipped == 0
    cam.stream_off()
    cam.stream_on()  # the same kind again: nothing more to compile
    assert warmed == [0]
    # Warming changes no frame: frames are a function of spec, sequence and start.
    fresh = FirmwareCamera("imx219", scene={"scene": "flat"}, size=(640, 480), pixel_format="RG10", hflip=True)
    assert np.array_equal(cam.render(plan).data, fresh.render(plan).data)


def test_a_new_kind_of_frame_while_streaming_compiles_outside_the_device_lock(monkeypatch):
    import threading

    from rollcam.firmware import imaging

    cam = FirmwareCamera("imx219", scene={"scene": "flat"}, size=(640, 480), pixel_format="RG10")
    cam.stream_on()
    monkeypatch.setattr(imaging, "_WARM_KINDS", set())
    lock_free = []
    render = imaging.Imager.render

    def probing_render(self, spec, seq, start_ns, shutter=None):
        probe = threading.Thread(target=lambda: lock_free.append(cam.lock.acquire(timeout=0) and
                                                                 (cam.lock.release() or True)))
        probe.start()
        probe.join()
        return render(self, spec, seq, start_ns, shutter)

    monkeypatch.setattr(imaging.Imager, "render", probing_render)
    cam.set_options({"scene": "street", "speed": "fast"})  # e.g. SCENE over the serial line, mid-stream
    assert lock_free == [True] and imaging.kernel_kind(cam.spec) in imaging._WARM_KINDS
    cam.update(gain=2.0)  # same kind: nothing rendered ahead
    assert lock_free == [True]


_COLD_STREAM = """
from rollcam.emu.v4l2 import Device
with Device.open("imx219", scene={"scene": "street"}, size=(640, 480), realtime=True) as d:
    d.set_format(640, 480, "RG10")
    d.controls["hflip"].value = 1
    bufs = list(d.stream(frames=2))  # DQBUF's default 5 s timeout
print(len(bufs), bufs[0].fourcc)
"""


@pytest.mark.slow
def test_a_real_time_raw_stream_on_a_cold_numba_cache_delivers_within_its_timeout(tmp_path):
    """A fresh machine (empty numba cache): the kernels compile at STREAMON, before the device clock starts,
    so the first DQBUF does not time out waiting for them (a functional check; no speed target)."""
    import os
    import subprocess
    import sys

    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    res = subprocess.run([sys.executable, "-c", _COLD_STREAM], env=env, capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.split() == ["2", "BA10"]
    assert any((tmp_path / "numba").rglob("*.nbc"))  # it did compile afresh
