"""The firmware camera's output formats: the emulated ISP's processed ones and the sensor's raw ones.

``FORMATS`` are the processed formats: BGR renders converted by ``convert(image, fourcc)``, the conversion
point of the V4L2 and HTTP transports (UVC's wire formats are in ``rollcam.emu.uvc.convert``). A sensor's raw
fourccs (Bayer or mono samples, unpacked or CSI-2 packed, from its hw_config ``formats``) bypass the ISP, as
on a near-sensor camera: ``RawFormat`` describes them to devices and ``to_bgr`` turns a raw frame into a
preview image (``rollcam.sim.isp``) for transports that can only show pictures (HTTP MJPEG). Pixel layouts
are ``rollcam.sim.formats``'s.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from rollcam.sim import formats as sf
from rollcam.sim.errors import ConfigError
from rollcam.sim.formats import bgr_to_yuyv
from rollcam.sim.frame import Frame
from rollcam.sim.hwconfig import SensorConfig
from rollcam.sim.isp import IspParams, preview


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


@dataclass(frozen=True)
class RawFormat:
    """A raw sensor format (samples straight from the ADC, no ISP) as a device describes it to applications."""

    fourcc: str

    @property
    def layout(self) -> sf.PixelFormat:
        """Bits, packing and CFA of the format (``rollcam.sim.formats``)."""
        return sf.pixel_format(self.fourcc)

    @property
    def description(self) -> str:
        """The kernel's style of name: '10-bit Bayer RGRG/GBGB Packed', '10-bit Greyscale'."""
        f = self.layout
        kind = "Greyscale" if f.cfa == "mono" else f"Bayer {f.cfa[:2] * 2}/{f.cfa[2:] * 2}"
        return f"{f.bits}-bit {kind}{' Packed' if f.packing == 'csi2' else ''}"

    compressed = False

    def bytesperline(self, width: int) -> int:
        """Bytes of one line (CSI-2 packed: 5 bytes per 4 10-bit pixels, 3 per 2 12-bit pixels)."""
        return self.layout.bytesperline(width)

    def sizeimage(self, width: int, height: int) -> int:
        """Bytes of a frame."""
        return self.layout.sizeimage(width, height)


def is_raw(fourcc: str) -> bool:
    """True for a raw sensor fourcc (Bayer or mono samples) that is not one of the processed ``FORMATS``."""
    if fourcc in FORMATS:
        return False
    try:
        return sf.pixel_format(fourcc).is_raw
    except ConfigError:
        return False


def raw_formats(sensor: SensorConfig) -> list[str]:
    """The sensor's raw fourccs from its hw_config ``formats`` (unflipped Bayer order), in its order.

    A name the ISP also makes (GREY) stays the processed one.
    """
    return [f for f in sensor.formats if is_raw(f)]


def pixel_format(fourcc: str) -> PixelFormat | RawFormat:
    """The description of a processed or raw ``fourcc``; an unknown one is a ConfigError naming the known ones."""
    if fourcc in FORMATS:
        return FORMATS[fourcc]
    if is_raw(fourcc):
        return RawFormat(sf.pixel_format(fourcc).fourcc)
    raise ConfigError(f"pixel format {fourcc!r} is not one of {list(FORMATS)} or a raw sensor format")


def to_bgr(frame: Frame, sensor: SensorConfig) -> np.ndarray:
    """A frame's picture as 8-bit BGR: the render itself, or a raw frame through the preview ISP."""
    if not is_raw(frame.format):
        return frame.data
    f = sf.pixel_format(frame.format)
    samples = sf.decode_raw(frame.data, f.fourcc, frame.width)
    shift = sensor.bit_depth - f.bits  # a narrower format keeps the ADC's high bits
    black = sensor.noise.black_level_dn / (1 << shift)
    white = float((1 << f.bits) - 1)
    return preview(samples, f.cfa or "mono", IspParams(black_level_dn=min(black, white - 1), white_level_dn=white))


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
