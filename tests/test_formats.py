"""Pixel formats: the fourcc table, CSI-2 packing, mosaic and flips, the preview ISP (codecs: test_codecs.py)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rollcam.common.errors import ConfigError
from rollcam.sim import formats as F
from rollcam.sim.hwconfig import FOURCCS
from rollcam.sim.isp import IspParams, demosaic, preview


def test_table_agrees_with_hwconfig_fourccs():
    for fourcc, (order, bits) in FOURCCS.items():
        if fourcc not in F.FORMATS:
            continue  # compressed formats (MJPG, H264) and others the emulator does not make
        f = F.FORMATS[fourcc]
        assert f.bits == bits, fourcc
        if order is not None and fourcc != "GREY":
            assert f.cfa == order, fourcc


@pytest.mark.parametrize(("fourcc", "w", "h", "bpl", "size", "shape"), [
    ("pRAA", 1920, 1080, 2400, 2400 * 1080, (1080, 2400)),
    ("pRAA", 6, 2, 8, 16, (2, 8)),  # ceil(6 * 10 / 8) = 8
    ("pRCC", 1920, 1080, 2880, 2880 * 1080, (1080, 2880)),
    ("RG10", 640, 480, 1280, 1280 * 480, (480, 640)),
    ("RGGB", 640, 480, 640, 640 * 480, (480, 640)),
    ("YUYV", 640, 480, 1280, 1280 * 480, (480, 640, 2)),
    ("NV12", 640, 480, 640, 640 * 480 * 3 // 2, (720, 640)),
    ("BGR3", 640, 480, 1920, 1920 * 480, (480, 640, 3)),
    ("Y10 ", 640, 400, 1280, 1280 * 400, (400, 640)),
])
def test_bytesperline_sizeimage_shape(fourcc, w, h, bpl, size, shape):
    f = F.pixel_format(fourcc)
    assert (f.bytesperline(w), f.sizeimage(w, h), f.shape(w, h)) == (bpl, size, shape)


@pytest.mark.parametrize("fourcc", ["NV12", "YU12", "YUYV", "RG10", "pRAA", "XR24"])
def test_line_spans_of_bands_cover_every_plane(fourcc):
    """Bands of lines (odd boundaries included) cover the whole frame, chroma planes too, and a band's spans hold
    exactly the bytes its lines need: luma lines, and the chroma lines they share."""
    f = F.pixel_format(fourcc)
    w, h = 8, 6
    frame = np.zeros(f.sizeimage(w, h), np.uint8)
    for first, end in ((0, 3), (3, 5), (5, 6)):
        for lo, hi in f.line_spans(first, end, w, h):
            assert 0 <= lo < hi <= frame.size
            frame[lo:hi] += 1
    assert frame.min() >= 1  # every byte is in some band
    if fourcc == "NV12":  # luma rows 3 and 4 and the chroma row (line 1 of 3) that rows 2..3 share, then 4..5's
        assert F.pixel_format("NV12").line_spans(3, 5, w, h) == [(24, 40), (48 + 8, 48 + 24)]
    if fourcc == "YU12":
        assert F.pixel_format("YU12").line_spans(0, 2, w, h) == [(0, 16), (48, 52), (60, 64)]


def test_pixel_format_errors_and_short_names():
    assert F.pixel_format("Y10").fourcc == "Y10 "
    with pytest.raises(ConfigError, match="'XXXX'"):
        F.pixel_format("XXXX")


def test_csi2_raw10_layout_matches_the_kernel_docs():
    v = np.array([[0x3FF, 0x000, 0x155, 0x2AA, 0x001]], np.uint16)
    p = F.pack_csi2(v, 10)
    # High 8 bits of pixels 0..3, then their low 2 bits (pixel 0 in bits 1:0); a tail group of 1 pixel.
    assert p.tolist() == [[0xFF, 0x00, 0x55, 0xAA, 0b10_01_00_11, 0x00, 0b01]]
    assert F.unpack_csi2(p, 10, 5).tolist() == v.tolist()


def test_csi2_raw12_layout_matches_the_kernel_docs():
    v = np.array([[0xABC, 0x123, 0xFFF]], np.uint16)
    p = F.pack_csi2(v, 12)
    assert p.tolist() == [[0xAB, 0x12, 0x3C, 0xFF, 0x0F]]
    assert F.unpack_csi2(p, 12, 3).tolist() == v.tolist()


@settings(max_examples=60, deadline=None)
@given(bits=st.sampled_from([10, 12]), h=st.integers(1, 4), w=st.integers(1, 21), seed=st.integers(0, 2**32 - 1))
def test_csi2_round_trip(bits, h, w, seed):
    v = np.random.default_rng(seed).integers(0, 1 << bits, (h, w)).astype(np.uint16)
    p = F.pack_csi2(v, bits)
    assert p.shape == (h, -(-w * bits // 8))
    assert np.array_equal(F.unpack_csi2(p, bits, w), v)


def test_flipped_order():
    assert F.flipped_order("RGGB", hflip=True) == "GRBG"
    assert F.flipped_order("RGGB", vflip=True) == "GBRG"
    assert F.flipped_order("RGGB", hflip=True, vflip=True) == "BGGR"
    assert F.flipped_order("mono", hflip=True) == "mono"
    for order in F.BAYER_ORDERS:  # flipping twice restores the order
        assert F.flipped_order(F.flipped_order(order, True, True), True, True) == order


def test_flip_of_mosaic_is_mosaic_of_flipped_order():
    img = np.random.default_rng(0).integers(0, 255, (6, 8, 3)).astype(np.uint8)
    for order in F.BAYER_ORDERS:
        m = F.mosaic(img, order)
        assert np.array_equal(m[:, ::-1], F.mosaic(img[:, ::-1], F.flipped_order(order, hflip=True)))
        assert np.array_equal(m[::-1], F.mosaic(img[::-1], F.flipped_order(order, vflip=True)))


@pytest.mark.parametrize("order", F.BAYER_ORDERS)
def test_mosaic_then_demosaic_recovers_flat_colour(order):
    bgr = np.zeros((8, 8, 3), np.uint8)
    bgr[...] = (40, 120, 200)
    out = demosaic(F.mosaic(bgr, order), order)
    assert out[2:-2, 2:-2].reshape(-1, 3).tolist() == [[40, 120, 200]] * 16


def test_bayer_fourcc():
    assert F.bayer_fourcc("GRBG", 10, packed=True) == "pgAA"
    assert F.bayer_fourcc("BGGR", 8) == "BA81"
    assert F.bayer_fourcc("mono", 12) == "Y12 "


def test_preview_isp_black_white_and_gamma():
    raw = np.full((4, 4), 64, np.uint16)
    p = IspParams(black_level_dn=64, white_level_dn=1023)
    assert preview(raw, "RGGB", p).max() == 0
    raw[:] = 1023
    assert preview(raw, "RGGB", p).min() == 255
    raw[:] = 64 + round(0.214 * 959)  # linear 0.214 -> sRGB ~ 128
    assert abs(int(preview(raw, "mono", p)[0, 0, 0]) - 128) <= 1
    with pytest.raises(ConfigError):
        IspParams(black_level_dn=100, white_level_dn=50)


def test_preview_lookup_tables_equal_the_per_pixel_float32_steps():
    """``preview`` applies its steps as a table per channel; the result is the per-pixel definition's, bit for bit."""
    from rollcam.sim.isp import _LUT_BITS, _SRGB

    def per_pixel(raw, order, p):
        lin = (demosaic(raw, order).astype(np.float32) - np.float32(p.black_level_dn)) * np.float32(
            1.0 / (p.white_level_dn - p.black_level_dn))
        if order != "mono":
            lin *= np.array(p.wb_gains[::-1], np.float32)
        np.clip(lin, 0.0, 1.0, out=lin)
        if p.gamma is None:
            return np.round(lin * 255.0).astype(np.uint8)
        return _SRGB[(lin * ((1 << _LUT_BITS) - 1) + 0.5).astype(np.int32)]

    rng = np.random.default_rng(3)
    for order in ("RGGB", "GBRG", "mono"):
        for dtype, top in ((np.uint16, 1023), (np.uint16, 4095), (np.uint8, 255)):
            raw = rng.integers(0, top + 1, (36, 50)).astype(dtype)
            for p in (IspParams(64, top * 0.9), IspParams(16, top, (1.7, 1.0, 1.3), gamma=None),
                      IspParams(0, top, (2.0, 1.0, 0.5))):
                assert np.array_equal(preview(raw, order, p), per_pixel(raw, order, p)), (order, dtype, p)
