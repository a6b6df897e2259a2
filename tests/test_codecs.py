"""The codec table: every fourcc round-trips, previews are 8-bit BGR less the black level, errors name values."""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rollcam.common.errors import ConfigError, ProtocolError
from rollcam.host import open_camera
from rollcam.sim import formats as F
from rollcam.sim.codecs import CODECS, JPEG_QUALITY, Levels, bgr_to_rgb, codec, grey_u8, preview_frame, transcode
from rollcam.sim.frame import Frame
from rollcam.sim.hwconfig import load_sensor
from rollcam.sim.timing import Readout

W, H = 16, 12
RNG = np.random.default_rng(7)
BLOCKY = np.repeat(np.repeat(RNG.integers(30, 220, (H // 4, W // 4, 3)), 4, 0), 4, 1).astype(np.uint8)
"""A BGR picture constant on 4x4 blocks: chroma subsampling loses nothing but rounding."""
SMOOTH = np.stack(np.broadcast_arrays(*np.ogrid[40:40 + 10 * H:10, 30:30 + 8 * W:8], 100), axis=2).astype(np.uint8)
"""A smooth BGR gradient, what JPEG is made for."""


def frame(data: np.ndarray, fourcc: str, meta: dict | None = None) -> Frame:
    return Frame(data=data, format=fourcc, sequence=0, timestamp_ns=0, line_time_ns=0, readout=Readout.TOP_TO_BOTTOM,
                 exposure_ns=0, size=(W, H), meta=meta or {})


def test_the_table_has_a_row_for_every_fourcc_and_mjpg():
    assert set(CODECS) == {*F.FORMATS, "MJPG"}
    assert all(c.layout is F.FORMATS.get(f) for f, c in CODECS.items())
    assert codec("Y10") is CODECS["Y10 "] and codec("MJPG").compressed and not codec("YUYV").compressed
    assert [f for f, c in CODECS.items() if c.raw] == [f for f, p in F.FORMATS.items() if p.is_raw]


@pytest.mark.parametrize("fourcc", [f for f, c in CODECS.items() if c.raw])
def test_raw_formats_round_trip_samples_and_keep_the_high_bits_of_a_wider_adc(fourcc):
    c, f = codec(fourcc), F.FORMATS[fourcc]
    samples = RNG.integers(0, 1 << f.bits, (H, W)).astype(np.uint16)
    wire = c.encode(samples)
    assert wire.shape == f.shape(W, H) and wire.dtype == f.dtype and wire.nbytes == f.sizeimage(W, H)
    for carried in (wire, wire.tobytes(), wire.reshape(-1).view(np.uint8)):  # any form of the same bytes
        back = c.decode(carried, W, H)
        assert back.dtype == np.uint16 and np.array_equal(back, samples)
    adc = RNG.integers(0, 1 << 16, (H, W)).astype(np.uint16)  # a 16-bit ADC: the format keeps the high bits
    assert np.array_equal(c.decode(c.encode(adc, sample_bits=16), W, H), adc >> (16 - f.bits))
    if f.bits > 8:
        with pytest.raises(ConfigError, match="more than the sensor's 8-bit"):
            c.encode(samples, sample_bits=8)
    if fourcc != "GREY":  # GREY also takes a picture (its luma)
        with pytest.raises(ConfigError, match="raw sensor format"):
            c.encode(BLOCKY)


@settings(max_examples=40, deadline=None)
@given(fourcc=st.sampled_from(["pRAA", "pRCC", "Y10P", "Y12P"]), w=st.integers(1, 23), h=st.integers(1, 4),
       seed=st.integers(0, 2**32 - 1))
def test_csi2_rows_round_trip_any_width(fourcc, w, h, seed):
    c = codec(fourcc)
    v = np.random.default_rng(seed).integers(0, 1 << c.layout.bits, (h, w)).astype(np.uint16)
    assert np.array_equal(c.decode(c.encode(v).tobytes(), w, h), v)


@pytest.mark.parametrize(("fourcc", "tolerance"), [("BGR3", 0), ("RGB3", 0), ("XR24", 0), ("YUYV", 6), ("UYVY", 6),
                                                   ("NV12", 6), ("YU12", 6), ("MJPG", 16)])
def test_picture_formats_round_trip_bgr(fourcc, tolerance):
    c = codec(fourcc)
    picture = SMOOTH if fourcc == "MJPG" else BLOCKY
    wire = c.encode(picture)
    if c.layout is not None:
        assert wire.shape == c.layout.shape(W, H) and wire.nbytes == c.layout.sizeimage(W, H)
    else:
        assert wire.ndim == 1 and bytes(wire[:2]) == b"\xff\xd8"  # a JPEG
    back = c.decode(wire.tobytes(), W, H)
    assert back.shape == (H, W, 3) and back.dtype == np.uint8
    assert np.abs(back.astype(int) - picture).max() <= tolerance
    assert np.array_equal(c.preview(wire, W, H, Levels(64, 10)), back)  # levels mean nothing to a picture
    with pytest.raises(ConfigError, match="8-bit BGR"):
        c.encode(BLOCKY.astype(np.uint16))


def test_rgb_and_xr24_and_the_yuv_layouts_are_the_kernels():
    assert np.array_equal(codec("RGB3").encode(BLOCKY), BLOCKY[..., ::-1])
    xr24 = codec("XR24").encode(BLOCKY)
    assert np.array_equal(xr24[..., :3], BLOCKY)  # B G R X
    nv12, yu12 = codec("NV12").encode(BLOCKY), codec("YU12").encode(BLOCKY)
    assert np.array_equal(nv12[:H], yu12[:H])  # the same Y plane
    n = (H // 2) * (W // 2)
    assert np.array_equal(nv12[H:].reshape(-1)[0::2], yu12[H:].reshape(-1)[:n])  # U interleaved first
    yuyv, uyvy = codec("YUYV").encode(BLOCKY), codec("UYVY").encode(BLOCKY)
    assert np.array_equal(yuyv[..., 0], uyvy[..., 1]) and np.array_equal(yuyv[..., 1], uyvy[..., 0])


@pytest.mark.parametrize(("fourcc", "code"), [("YUYV", cv2.COLOR_BGR2YUV_YUYV), ("UYVY", cv2.COLOR_BGR2YUV_UYVY)])
def test_the_422_packings_are_opencvs_bytes(fourcc, code):
    """rollcam's own 4:2:2 kernels (less CPU than OpenCV's) sends exactly what OpenCV's conversion would: random
    pictures of several sizes, every pair of extreme pixels, and a non-contiguous view."""
    import itertools

    rng = np.random.default_rng(3)
    pictures = [rng.integers(0, 256, (h, w, 3), dtype=np.uint8) for h, w in ((1, 2), (7, 10), (120, 160), (37, 642))]
    extremes = np.array([0, 1, 2, 127, 128, 129, 253, 254, 255], np.uint8)
    pictures.append(np.array(list(itertools.product(extremes, repeat=6)), np.uint8).reshape(81, -1, 3))
    pictures.append(rng.integers(0, 256, (40, 100, 3), dtype=np.uint8)[::2, 10:90])  # a strided view
    for bgr in pictures:
        assert np.array_equal(codec(fourcc).encode(bgr), cv2.cvtColor(np.ascontiguousarray(bgr), code)), bgr.shape


def test_mjpg_is_one_encoder_with_one_quality_default():
    c = codec("MJPG")
    assert np.array_equal(c.encode(BLOCKY), c.encode(BLOCKY, quality=JPEG_QUALITY))
    assert c.encode(BLOCKY, quality=20).size < c.encode(BLOCKY, quality=95).size
    assert c.decode(c.encode(BLOCKY[..., 1])).shape == (H, W, 3)  # a grey JPEG decodes to BGR too
    for bad in (0, 101, 8.5, True):
        with pytest.raises(ConfigError, match=f"JPEG quality {bad!r} is not an integer in 1..100"):
            c.encode(BLOCKY, quality=bad)
    for bad in (b"", b"not a jpeg"):
        with pytest.raises(ProtocolError, match="does not decode"):
            c.decode(bad)


def test_grey_is_luma_of_a_picture_or_a_mono_sensors_samples():
    c = codec("GREY")
    assert np.array_equal(c.encode(BLOCKY), cv2.cvtColor(BLOCKY, cv2.COLOR_BGR2GRAY))
    assert np.array_equal(c.encode(np.array([[1023, 4]], np.uint16), sample_bits=10), [[255, 1]])
    luma = c.encode(BLOCKY)
    assert np.array_equal(c.preview(luma, W, H), np.repeat(luma[..., None], 3, 2))  # no levels: the picture
    assert c.preview(np.full((H, W), 16, np.uint8), W, H, Levels(64, 10)).max() == 0  # samples: 64 / 4 is black


@pytest.mark.parametrize("fourcc", ["RGGB", "RG10", "pRAA", "RG12", "Y10 ", "Y10P", "GREY"])
def test_raw_previews_subtract_the_black_level_scaled_to_the_formats_bits(fourcc):
    c, f = codec(fourcc), F.FORMATS[fourcc]
    levels = Levels(black_level_dn=256.0, bit_depth=12)  # a 12-bit sensor's black: 256 >> (12 - bits)
    black = 256 >> (12 - f.bits)
    wire = c.encode(np.full((H, W), black, np.uint16))
    assert c.preview(wire, W, H, levels).max() == 0
    assert c.preview(wire, W, H).min() > 0 or fourcc == "GREY"  # without levels 0 is black, this is grey
    white = c.encode(np.full((H, W), (1 << f.bits) - 1, np.uint16))
    assert c.preview(white, W, H, levels).min() == 255
    mid = c.preview(c.encode(np.full((H, W), black + ((1 << f.bits) - black) // 4, np.uint16)), W, H, levels)
    assert mid.shape == (H, W, 3) and mid.dtype == np.uint8 and 120 < mid.mean() < 150  # sRGB of ~0.25


def test_demosaic_puts_each_site_in_its_bayer_orders_channel():
    red = np.zeros((4, 4), np.uint16)
    red[0::2, 0::2] = 1023  # the red sites of an RGGB mosaic, the blue ones of BGGR
    for fourcc, lit in (("RG10", 2), ("BG10", 0)):
        px = codec(fourcc).preview(red, 4, 4)[1, 1]
        assert px[lit] > 0 and px.sum() == px[lit], fourcc
    packed = codec("pRAA").encode(red)
    assert np.array_equal(codec("pRAA").preview(packed, 4, 4), codec("RG10").preview(red, 4, 4))


def test_errors_name_the_fourcc_and_what_is_supported():
    with pytest.raises(ConfigError, match=r"'ZZZZ' has no codec; supported: \[.*'MJPG'.*'pRAA'"):
        codec("ZZZZ")
    with pytest.raises(ProtocolError, match="YUYV 16x12 frame needs 384 bytes, got 382"):
        codec("YUYV").decode(b"\0" * 382, W, H)
    with pytest.raises(ConfigError, match=r"YUYV needs an even width, got 15x12"):
        codec("YUYV").encode(BLOCKY[:, :15])
    with pytest.raises(ConfigError, match=r"NV12 needs an even width and height, got 16x11"):
        codec("NV12").encode(BLOCKY[:11])


def test_levels_come_from_a_raw_frames_meta_only_when_it_holds_that_sensors_samples():
    sensor = load_sensor("imx219")
    meta = {"black_level_dn": 64.0, "bit_depth": 10, "cfa": "RGGB"}
    assert Levels.of_frame(frame(np.zeros((H, W), np.uint16), "RG10", meta)) == Levels.of_sensor(sensor)
    assert Levels.of_frame(frame(np.zeros((H, W), np.uint8), "GREY", meta)) is None  # a colour sensor's luma
    assert Levels.of_frame(frame(BLOCKY, "BGR3", meta)) is None
    assert Levels.of_frame(frame(np.zeros((H, W), np.uint16), "RG10")) is None  # a raw frame from elsewhere


def test_emu_grey_on_a_colour_sensor_is_the_isp_luma():
    with open_camera("emu:imx219?format=GREY&size=64x48&scene=chart") as grey, \
            open_camera("emu:imx219?format=BGR3&physics=on&size=64x48&scene=chart") as bgr:
        g, b = grey.read(), bgr.read()
    assert g.format == "GREY" and g.data.shape == (48, 64) and g.data.dtype == np.uint8
    assert np.array_equal(g.data, cv2.cvtColor(b.data, cv2.COLOR_BGR2GRAY))
    assert np.array_equal(preview_frame(g), np.repeat(g.data[..., None], 3, 2))


def test_transcode_passes_a_frame_in_its_format_and_encodes_a_preview_otherwise():
    raw = frame(np.full((H, W), 64, np.uint16), "RG10", {"black_level_dn": 64.0, "bit_depth": 10, "cfa": "RGGB"})
    assert transcode(raw, "RG10") is raw.data
    assert np.array_equal(transcode(raw, "BGR3"), np.zeros((H, W, 3), np.uint8))  # black, less the black level
    assert np.array_equal(transcode(frame(BLOCKY, "BGR3"), "YUYV"), codec("YUYV").encode(BLOCKY))
    with pytest.raises(ConfigError, match="raw sensor format"):
        transcode(frame(BLOCKY, "BGR3"), "RG10")  # a picture cannot become sensor samples


_CODEC_CALLS = re.compile(r"imdecode|imencode|COLOR_YUV2|COLOR_BGR2YUV|COLOR_Bayer|YUV_YUYV|IMWRITE_JPEG")
_IMAGE_FILES = {"host/recording/capture.py",  # PNG / JPEG files on disk, not pixel formats on a wire
                "host/recording/demo.py",
                "host/shims/picamera2/request.py",  # picamera2's capture_file: PNG, BMP, ... (JPEG: the codec)
                "emu/http/view.py",  # the live view's snapshot download (PNG)
                "sim/instance_masks.py"}  # rollcam renders exported as labelled footage (PNG frames and masks)


def test_no_pixel_conversion_outside_the_codec_table():
    root = Path(__file__).resolve().parents[1]
    offenders = []
    for path in sorted(root.glob("*/**/*.py")):
        rel = path.relative_to(root).as_posix()
        # build/: a wheel build's copies of the tree; rollcam_out/: what commands wrote
        if rel.split("/")[0] in ("tests", "benchmarks", "build", "rollcam_out") or rel.startswith(".") or "/." in rel:
            continue
        if rel in _IMAGE_FILES or rel in ("sim/codecs.py", "sim/_yuv_kernels.py", "sim/isp.py"):  # the table, kernel
            continue
        if _CODEC_CALLS.search(path.read_text()):
            offenders.append(rel)
    assert offenders == []


def test_encode_image_writes_the_file_format_asked_for():
    import cv2
    from rollcam.sim.codecs import encode_image

    img = (np.arange(24 * 32 * 3) % 251).astype(np.uint8).reshape(24, 32, 3)
    png = encode_image(img, "png")
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    np.testing.assert_array_equal(cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR), img)
    assert encode_image(img, "jpg", (cv2.IMWRITE_JPEG_QUALITY, 85))[:2] == b"\xff\xd8"


def test_grey_and_channel_order_helpers_are_the_luma_and_the_swap():
    """``grey_u8`` (optical flow's grey) and ``bgr_to_rgb`` (footage's channel order), checked against numpy."""
    rng = np.random.default_rng(38)
    bgr = rng.integers(0, 256, (9, 11, 3), dtype=np.uint8)
    luma = np.rint(bgr[..., 0] * 0.114 + bgr[..., 1] * 0.587 + bgr[..., 2] * 0.299)
    assert np.abs(grey_u8(bgr).astype(int) - luma).max() <= 1  # BT.601 in OpenCV's fixed point
    assert np.array_equal(grey_u8(bgr[..., ::-1], "rgb"), grey_u8(bgr))
    bgra = np.dstack([bgr, np.full((9, 11), 7, np.uint8)])
    assert np.array_equal(grey_u8(bgra), grey_u8(bgr)) and np.array_equal(grey_u8(bgra[..., [2, 1, 0, 3]], "rgb"),
                                                                         grey_u8(bgr))
    assert np.array_equal(grey_u8(bgr[..., 0]), bgr[..., 0])
    with pytest.raises(ConfigError, match="no grey"):
        grey_u8(np.zeros((4, 4, 2), np.uint8))
    assert np.array_equal(bgr_to_rgb(bgr), bgr[..., ::-1])
    deep = rng.integers(0, 65536, (5, 6, 4), dtype=np.uint16)
    assert bgr_to_rgb(deep).dtype == np.uint16 and np.array_equal(bgr_to_rgb(deep), deep[..., [2, 1, 0, 3]])
    assert np.array_equal(bgr_to_rgb(bgr[..., 0]), bgr[..., 0])
