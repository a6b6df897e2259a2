"""The emulated ISP's output formats: BGR renders converted to what a device streams.

``convert(image, fourcc)`` is the conversion point of the V4L2 and HTTP transports (UVC's wire formats are in
``rollcam.emu.uvc.convert``); both defer to ``rollcam.sim.formats`` for the pixel layouts and to
``encode_jpeg`` here for MJPEG.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from rollcam.sim.errors import ConfigError
from rollcam.sim.formats import bgr_to_yuyv


@dataclass(frozen=True)
class PixelFormat:
    """A streamable format: fourcc, description, bytes per pixel (0 = compressed), V4L2 compressed flag."""

    fourcc: str
    description: str
    bytes_per_pixel: int

    @property
    def compressed(self) -> bool:
        """True for formats whose frames vary in size (MJPG)."""
        return self.bytes_per_pixel == 0

    def bytesperline(self, width: int) -> int:
        """Bytes of one line (0 for compressed formats, as V4L2 reports them)."""
        return width * self.bytes_per_pixel

    def sizeimage(self, width: int, height: int) -> int:
        """Buffer size a frame needs (a generous bound for compressed formats)."""
        return width * height * (self.bytes_per_pixel or 3)


FORMATS: dict[str, PixelFormat] = {f.fourcc: f for f in (
    PixelFormat("YUYV", "YUYV 4:2:2", 2),
    PixelFormat("BGR3", "24-bit BGR 8-8-8", 3),
    PixelFormat("RGB3", "24-bit RGB 8-8-8", 3),
    PixelFormat("GREY", "8-bit Greyscale", 1),
    PixelFormat("MJPG", "Motion-JPEG", 0),
)}
"""Formats the emulated ISP produces, in the order devices enumerate them."""

JPEG_QUALITY = 85


def pixel_format(fourcc: str) -> PixelFormat:
    """The PixelFormat of ``fourcc``; an unknown one is a ConfigError naming the known ones."""
    try:
        return FORMATS[fourcc]
    except KeyError:
        raise ConfigError(f"pixel format {fourcc!r} is not one of {list(FORMATS)}") from None


def encode_jpeg(image_bgr: np.ndarray, quality: int = JPEG_QUALITY) -> bytes:
    """A baseline JPEG of a BGR (or grey) image."""
    ok, buf = cv2.imencode(".jpg", image_bgr, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ConfigError(f"JPEG encoding failed for an image of shape {image_bgr.shape!r}")
    return buf.tobytes()


def convert(image_bgr: np.ndarray, fourcc: str, quality: int = JPEG_QUALITY) -> np.ndarray:
    """A BGR8 image as ``fourcc`` data: (h, w, c) arrays for raw formats, a 1-D uint8 array for MJPG."""
    if fourcc == "BGR3":
        return image_bgr
    if fourcc == "YUYV":
        return bgr_to_yuyv(image_bgr)
    if fourcc == "RGB3":
        return cv2.cvtColor(image_bgr, cv2.COLOR_BGR2RGB)
    if fourcc == "GREY":
        return cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY)
    if fourcc == "MJPG":
        return np.frombuffer(encode_jpeg(image_bgr, quality), dtype=np.uint8)
    raise ConfigError(f"pixel format {fourcc!r} is not one of {list(FORMATS)}")
