"""The stream formats picamera2 names (libcamera's pixel-format names), by kind, and checks on them."""

from __future__ import annotations

_BAYER_ORDERS = ("BGGR", "GBRG", "GRBG", "RGGB")

YUV_FORMATS = {"NV21", "NV12", "YUV420", "YVU420", "YVYU", "YUYV", "UYVY", "VYUY"}
RGB_FORMATS = {"BGR888", "RGB888", "XBGR8888", "XRGB8888", "RGB161616", "BGR161616"}
BAYER_FORMATS = {f"S{order}{bits}{suffix}" for order in _BAYER_ORDERS for bits in (8, 10, 12, 16)
                 for suffix in ("", "_CSI2P") if not (suffix and bits in (8, 16))}
BAYER_FORMATS |= {f"{order}_PISP_COMP1" for order in _BAYER_ORDERS}
MONO_FORMATS = {"R8", "R10", "R12", "R16", "R8_CSI2P", "R10_CSI2P", "R12_CSI2P"}
ALL_FORMATS = YUV_FORMATS | RGB_FORMATS | BAYER_FORMATS | MONO_FORMATS


def is_YUV(fmt: str) -> bool:
    """True for a YUV format."""
    return fmt in YUV_FORMATS


def is_RGB(fmt: str) -> bool:
    """True for an RGB format."""
    return fmt in RGB_FORMATS


def is_Bayer(fmt: str) -> bool:
    """True for a Bayer (raw colour) format."""
    return fmt in BAYER_FORMATS


def is_mono(fmt: str) -> bool:
    """True for a raw monochrome format."""
    return fmt in MONO_FORMATS


def is_raw(fmt: str) -> bool:
    """True for a raw sensor format (Bayer or mono)."""
    return is_Bayer(fmt) or is_mono(fmt)


def assert_format_valid(fmt: str) -> None:
    """ValueError unless ``fmt`` is a format picamera2 knows."""
    if fmt not in ALL_FORMATS:
        raise ValueError(f"Invalid format: {fmt}. Valid formats are: {ALL_FORMATS}")
