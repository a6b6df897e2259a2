"""The emulated V4L2 device: kernel semantics (formats, controls, buffer queue, errnos), pacing and faults."""

from __future__ import annotations

import errno
import itertools
from fractions import Fraction

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rollcam.common.errors import ConfigError, DeviceError
from rollcam.emu.v4l2 import Device, V4L2Error, raw
from rollcam.emu.v4l2 import functions as fn
from rollcam.sim import formats as sim_formats


def dev(**kw) -> Device:
    kw.setdefault("realtime", False)
    return Device.open("imx219", scene={"scene": "flat"}, size=(640, 480), **kw)


def errno_of(call, *args, **kw) -> int:
    with pytest.raises(V4L2Error) as info:
        call(*args, **kw)
    assert isinstance(info.value, DeviceError) and isinstance(info.value, OSError)
    return info.value.errno


def test_querycap_and_enumeration():
    with dev() as d:
        cap = d.info
        assert cap.driver == "rollcam" and cap.device_caps & raw.Cap.VIDEO_CAPTURE
        assert cap.device_caps & raw.Cap.STREAMING and cap.capabilities & raw.Cap.DEVICE_CAPS
        fourccs = [f.pixelformat for f in fn.enum_formats(d.driver)]
        assert {"YUYV", "BGR3", "MJPG"} <= set(fourccs)
        sizes = [(s.width, s.height) for s in fn.enum_frame_sizes(d.driver, "YUYV")]
        assert (1920, 1080) in sizes and (640, 480) in sizes
        (ival,) = fn.enum_frame_intervals(d.driver, "YUYV", 1920, 1080)
        assert Fraction(ival.numerator, ival.denominator) == Fraction(1763 * 3448, 182_400_000)
        assert fn.enum_frame_intervals(d.driver, "YUYV", 123, 45) == []
        assert errno_of(d.driver.ioctl, raw.Ioctl.ENUM_FRAMEINTERVALS, raw.FrmIval(0, "YUYV", 123, 45)) == errno.EINVAL


def test_try_fmt_rounds_to_a_supported_size_and_format():
    with dev() as d:
        f = fn.try_format(d.driver, 1900, 1000, "XXXX")
        assert (f.width, f.height, f.pixelformat) == (1920, 1080, "YUYV")
        assert f.bytesperline == 3840 and f.sizeimage == 3840 * 1080
        assert fn.get_format(d.driver).width == 640  # TRY changes nothing
        f = d.set_format(600, 500, "BGR3")
        assert (f.width, f.height, f.bytesperline) == (640, 480, 1920)


def test_processed_formats_enumerate_in_order_with_v4l2_descriptions_and_sizes():
    with dev() as d:
        descs = [(f.pixelformat, f.description, f.flags) for f in fn.enum_formats(d.driver)][:5]
        assert descs == [("YUYV", "YUYV 4:2:2", 0), ("BGR3", "24-bit BGR 8-8-8", 0), ("RGB3", "24-bit RGB 8-8-8", 0),
                         ("GREY", "8-bit Greyscale", 0), ("MJPG", "Motion-JPEG", 1)]  # V4L2_FMT_FLAG_COMPRESSED
        for fourcc, bpl, space in (("YUYV", 1280, raw.Colorspace.SRGB), ("RGB3", 1920, raw.Colorspace.SRGB),
                                   ("GREY", 640, raw.Colorspace.SRGB), ("MJPG", 0, raw.Colorspace.JPEG),
                                   ("RG10", 1280, raw.Colorspace.RAW)):
            f = fn.try_format(d.driver, 640, 480, fourcc)
            size = 640 * 480 * 3 if fourcc == "MJPG" else bpl * 480  # MJPG: a generous bound, the BGR frame's
            assert (f.pixelformat, f.bytesperline, f.sizeimage, f.colorspace) == (fourcc, bpl, size, space)


def test_s_fmt_reqbufs_streamon_misuse_gives_kernel_errnos():
    with dev() as d:
        h = d.driver
        assert errno_of(fn.stream_on, h) == errno.EINVAL  # no buffers
        assert errno_of(fn.dequeue_buffer, h) == errno.EINVAL  # not streaming
        assert errno_of(fn.request_buffers, h, 2, raw.Memory.USERPTR) == errno.EINVAL
        assert fn.request_buffers(h, 1) == 2  # clamped to the minimum
        assert fn.request_buffers(h, 100) == raw.VIDEO_MAX_FRAME
        assert errno_of(fn.set_format, h, 1920, 1080, "YUYV") == errno.EBUSY  # buffers allocated
        assert errno_of(fn.queue_buffer, h, 99) == errno.EINVAL
        fn.queue_buffer(h, 0)
        assert errno_of(fn.queue_buffer, h, 0) == errno.EINVAL  # already queued
        fn.stream_on(h)
        fn.stream_on(h)  # a second STREAMON is a no-op
        assert errno_of(fn.request_buffers, h, 4) == errno.EBUSY
        assert errno_of(fn.set_control, h, raw.CID.HFLIP, 1) == errno.EBUSY  # flips grabbed while streaming
        buf, data = fn.dequeue_buffer(h)
        assert buf.index == 0 and buf.bytesused == 640 * 480 * 3 == data.size  # BGR3, the spec's default
        assert errno_of(fn.dequeue_buffer, h, block=False) == errno.EAGAIN  # nothing queued, nothing done
        fn.stream_off(h)
        fn.stream_off(h)
        assert fn.request_buffers(h, 0) == 0
        d.set_format(1920, 1080, "YUYV")


def test_controls_have_kernel_ids_ranges_and_side_effects():
    with dev() as d:
        h = d.driver
        q = fn.query_control(h, raw.CID.EXPOSURE)
        assert q.name == "Exposure" and q.type == raw.CtrlType.INTEGER and q.maximum == 1763 - 4
        assert fn.query_control(h, raw.CID.PIXEL_RATE).flags & raw.CtrlFlag.READ_ONLY
        assert fn.get_control(h, raw.CID.PIXEL_RATE) == 182_400_000
        assert fn.get_control(h, raw.CID.HBLANK) == 3448 - 640
        assert errno_of(fn.set_control, h, raw.CID.PIXEL_RATE, 1) == errno.EACCES
        assert errno_of(fn.get_control, h, 0x00980999) == errno.EINVAL
        before = fn.get_frame_interval(h)
        assert fn.set_control(h, raw.CID.VBLANK, 2520) == 2520
        n, dd = fn.get_frame_interval(h)
        assert Fraction(n, dd) == Fraction(3000 * 3448, 182_400_000) != Fraction(*before)
        assert fn.query_control(h, raw.CID.EXPOSURE).maximum == 2996
        assert fn.set_control(h, raw.CID.EXPOSURE, 10**6) == 2996  # clamped, as the control framework does
        fn.set_control(h, raw.CID.VBLANK, 100)
        assert fn.get_control(h, raw.CID.EXPOSURE) == 580 - 4  # exposure follows the shorter frame
        menu = [fn.query_menu(h, raw.CID.TEST_PATTERN, i).name for i in range(5)]
        assert menu == ["none", "bars", "solid", "fade_bars", "pn9"]
        assert errno_of(fn.set_control, h, raw.CID.TEST_PATTERN, 9) == errno.EINVAL
        n, dd = fn.set_frame_interval(h, 1, 15)
        assert abs(Fraction(n, dd) - Fraction(1, 15)) < Fraction(1, 10_000)


def test_test_pattern_control_reaches_the_buffers():
    with dev() as d:
        d.set_format(640, 480, "BGR3")
        d.controls["test_pattern"].value = 1  # bars
        (b,) = list(d.stream(frames=1))
        img = b.image()
        assert img.shape == (480, 640, 3) and tuple(img[0, 0]) == (255, 255, 255) and tuple(img[0, -1]) == (0, 0, 0)


@pytest.mark.parametrize("fourcc", ["YUYV", "BGR3", "MJPG", "GREY", "RGB3"])
def test_formats_decode_to_the_same_picture(fourcc):
    with dev() as ref, dev() as d:
        ref.set_format(640, 480, "BGR3")
        d.set_format(640, 480, fourcc)
        for x in (ref, d):
            x.controls["test_pattern"].value = 3  # fade-to-grey bars: colour and gradient
        want = next(ref.stream(frames=1)).image()
        got = next(d.stream(frames=1)).image()
        if fourcc == "GREY":
            want = cv2.cvtColor(cv2.cvtColor(want, cv2.COLOR_BGR2GRAY), cv2.COLOR_GRAY2BGR)  # previews are BGR
        assert np.abs(got.astype(int) - want).mean() < 6


@pytest.mark.parametrize("fourcc", ["NV12", "YU12", "YUYV"])
def test_a_realtime_buffer_filled_band_by_band_holds_every_plane(fourcc):
    """The real-time pump fills a buffer band by band; a 4:2:0 frame's chroma planes lie after all its luma
    lines, so a fill by luma lines alone left them zero (a green picture)."""
    with dev() as want_dev, dev(realtime=True) as d:
        for x in (want_dev, d):
            x.set_format(640, 480, fourcc)
            x.controls["test_pattern"].value = 3  # colour bars: the same picture in every frame
        want = next(want_dev.stream(frames=1))
        got = next(d.stream(frames=1))
        assert got.data.size == want.data.size == 640 * 480 * (2 if fourcc == "YUYV" else 3 / 2)
        assert np.array_equal(got.data, want.data)


@pytest.mark.parametrize("sensor", ["imx477", "imx219"])
def test_a_size_no_mode_has_is_offered_and_kept(sensor):
    """``size=640x480`` on an imx477 (no such mode): ENUM_FRAMESIZES lists it after the modes, TRY_FMT(G_FMT) and
    S_FMT give it back, ENUM_FRAMEINTERVALS gives the default mode's rate, and S_FMT to a mode and back works."""
    with Device.open(sensor, scene={"scene": "flat"}, size=(320, 240), realtime=False) as d:
        modes = [(m.width, m.height) for m in d.driver.camera.sensor.modes]
        assert (320, 240) not in modes
        sizes = [(s.width, s.height) for s in fn.enum_frame_sizes(d.driver, "YUYV")]
        assert sizes == [*modes, (320, 240)]
        g = fn.get_format(d.driver)
        assert (g.width, g.height) == (320, 240)
        assert fn.try_format(d.driver, 320, 240, g.pixelformat) == g
        (ival,) = fn.enum_frame_intervals(d.driver, "YUYV", 320, 240)
        t = d.driver.camera.sensor.timing(d.driver.camera.sensor.mode())
        assert Fraction(ival.numerator, ival.denominator) == Fraction(t.frame_period_pck, t.pixel_rate_hz)
        assert fn.get_frame_interval(d.driver) == (ival.numerator, ival.denominator)
        f = d.set_format(*modes[-1], "YUYV")
        assert (f.width, f.height) == modes[-1]
        assert (320, 240) in [(s.width, s.height) for s in fn.enum_frame_sizes(d.driver, "YUYV")]  # still offered
        assert (d.set_format(320, 240, "NV12").width, fn.get_format(d.driver).height) == (320, 240)
        assert next(d.stream(frames=1)).image().shape == (240, 320, 3)


def test_an_odd_size_no_mode_has_is_refused_naming_the_modes():
    """An odd scaled size cannot carry YUV chroma or a Bayer tile: the device streamed nothing (its pump failed
    to encode the first frame) where a real driver aligns to 2 pixels; it is refused when the camera is made."""
    with pytest.raises(ConfigError, match=r"641x480 is no mode of imx477 \(4056x3040, .*odd side"):
        Device.open("imx477", size=(641, 480))


def test_sequence_gaps_on_dropped_buffers_and_error_flag():
    with dev(faults="drop=40%,error=30%,seed=7") as d:
        bufs = list(d.stream(frames=30))
        seqs = [b.sequence for b in bufs]
        assert seqs == sorted(seqs) and seqs[-1] + 1 == 30 + d.driver.fault_stats.dropped
        assert d.driver.fault_stats.dropped > 0 and len(set(np.diff(seqs))) > 1
        assert sum(b.error for b in bufs) == d.driver.fault_stats.errors > 0


def test_injected_ioctl_error_is_one_shot_and_disconnect_gives_enodev():
    with dev(faults="reqbufs=ENOMEM,disconnect=3") as d:
        h = d.driver
        assert errno_of(fn.request_buffers, h, 4) == errno.ENOMEM
        n = fn.request_buffers(h, 4)
        for i in range(n):
            fn.queue_buffer(h, i)
        fn.stream_on(h)
        for _ in range(3):
            fn.dequeue_buffer(h)
        assert errno_of(fn.dequeue_buffer, h) == errno.ENODEV
        assert errno_of(fn.querycap, h) == errno.ENODEV


def test_realtime_stream_has_exact_device_timestamps_and_monotonic_buffers():
    with dev(realtime=True, bands=4) as d:
        d.set_format(640, 480, "YUYV")
        bufs = list(d.stream(buffers=6, frames=6, timeout_s=10))
    timing = d.driver.camera.state.timing
    seqs = [b.sequence for b in bufs]
    assert seqs == sorted(seqs) and len(set(seqs)) == 6
    for a, b in itertools.pairwise(bufs):
        assert b.timestamp_ns - a.timestamp_ns == timing.frame_start_ns(b.sequence) - timing.frame_start_ns(a.sequence)
    assert all(b.flags & raw.BufFlag.TIMESTAMP_MONOTONIC and b.flags & raw.BufFlag.TSTAMP_SRC_SOE for b in bufs)


def test_blocking_dqbuf_times_out_without_a_queued_buffer():
    with dev(realtime=True) as d:
        h = d.driver
        fn.request_buffers(h, 2)
        fn.stream_on(h)
        assert errno_of(fn.dequeue_buffer, h, timeout_s=0.2) == errno.ETIMEDOUT
        assert h.stats.delivered == 0


_OPS = st.lists(st.one_of(
    st.tuples(st.just("reqbufs"), st.integers(-1, 40)),
    st.tuples(st.just("qbuf"), st.integers(-1, 5)),
    st.tuples(st.just("dqbuf"), st.booleans()),
    st.tuples(st.sampled_from(["streamon", "streamoff", "querybuf", "s_fmt", "vflip"]), st.integers(0, 3)),
), max_size=25)
FUZZ_COUNTS: dict[str, int] = {}


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(ops=_OPS)
def _fuzz_ioctl_sequences(ops):
    FUZZ_COUNTS["ioctl"] = FUZZ_COUNTS.get("ioctl", 0) + 1
    with dev(faults="drop=20%,seed=1") as d:
        h, q = d.driver, d.driver.queue
        for op, n in ops:
            call = {"reqbufs": lambda n=n: fn.request_buffers(h, n), "qbuf": lambda n=n: fn.queue_buffer(h, n),
                    "dqbuf": lambda n=n: fn.dequeue_buffer(h, block=n, timeout_s=0.01),
                    "streamon": lambda: fn.stream_on(h), "streamoff": lambda: fn.stream_off(h),
                    "querybuf": lambda n=n: fn.query_buffer(h, n), "s_fmt": lambda: d.set_format(640, 480, "BGR3"),
                    "vflip": lambda n=n: fn.set_control(h, raw.CID.VFLIP, n % 2)}[op]
            try:
                call()
            except V4L2Error as exc:
                assert exc.errno in (errno.EINVAL, errno.EBUSY, errno.EAGAIN, errno.ETIMEDOUT), (op, exc)
            lists = [*q.queued, *q.done, *q.active]
            assert len(lists) == len(set(lists)) <= len(q.slots)  # a buffer is in one place at most
            for slot in q.slots:
                queued = bool(slot.info.flags & raw.BufFlag.QUEUED)
                assert queued == (slot.info.index in q.queued or slot.info.index in q.active), (op, slot.info)
            assert q.streaming == h.camera.streaming


def test_fuzz_ioctl_sequences_keep_the_queue_consistent():
    FUZZ_COUNTS["ioctl"] = 0
    _fuzz_ioctl_sequences()
    assert FUZZ_COUNTS["ioctl"] >= 100
    print(f"V4L2 ioctl-sequence fuzz: {FUZZ_COUNTS['ioctl']} sequences")


@pytest.mark.parametrize("fourcc", [f for f, p in sim_formats.FORMATS.items() if not p.is_raw])
def test_every_processed_format_the_camera_takes_is_one_v4l2_describes_and_streams(fourcc):
    """A format the camera spec accepts (``emu:...&format=NV12``) is one the V4L2 device enumerates, sets and
    streams in buffers of its sizeimage (NV12 was accepted by the spec but unknown to the device)."""
    with Device.open("imx219", realtime=False) as dev:
        fmt = dev.set_format(640, 480, fourcc)
        assert fmt.pixelformat == fourcc
        assert fourcc in dev.driver.camera.formats
        buf = next(iter(dev.stream(frames=1)))
        assert len(buf.data) == fmt.sizeimage
        assert buf.image().shape == (480, 640, 3)
