"""The firmware camera's output formats: the emulated ISP's processed ones and the sensor's raw ones.

``FORMATS`` are the processed formats: BGR renders converted by ``convert(image, fourcc)``, the conversion
point of the V4L2 and HTTP transports (UVC's wire formats are in ``rollcam.emu.uvc.convert``). A sensor's raw
fourccs (Bayer or mono samples, unpacked or CSI-2 packed, from its hw_config ``formats``) bypass the ISP, as
on a near-sensor camera. ``device_format`` describes either kind to devices as a ``DeviceFormat`` (the V4L2
description; layout, bytesperline and sizeimage are ``rollcam.sim.formats``'s, MJPG being the one compressed
format), and ``to_bgr`` turns a raw frame into a preview image (``rollcam.sim.isp``) for transports that can
only show pictures (HTTP MJPEG).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.sim import formats as sf
from rollcam.sim.formats import bgr_to_yuyv
from rollcam.sim.frame import Frame
from rollcam.sim.hwconfig import SensorConfig
from rollcam.sim.isp import IspParams, preview

JPEG_QUALITY = 85

_PROCESSED = (  # the emulated ISP's formats, in the order devices enumerate them, with V4L2's descriptions
    ("YUYV", "YUYV 4:2:2"),
    ("BGR3", "24-bit BGR 8-8-8"),
    ("RGB3", "24-bit RGB 8-8-8"),
    ("GREY", "8-bit Greyscale"),
    ("MJPG", "Motion-JPEG"),
)
COMPRESSED = frozenset({"MJPG"})
"""Processed fourccs whose frames vary in size; ``rollcam.sim.formats`` has no layout for them."""

_JPEG_BOUND = sf.pixel_format("BGR3")  # a JPEG frame never needs more bytes than the BGR frame it encodes


@dataclass(frozen=True)
class DeviceFormat:
    """A streamable fourcc as a device describes it: V4L2 description and whether it is raw sensor samples.

    Layout and sizes are ``layout``'s (a ``rollcam.sim.formats`` entry); ``layout`` is None for MJPG, the one
    compressed format.
    """

    fourcc: str
    description: str
    layout: sf.PixelFormat | None
    raw: bool = False

    @property
    def compressed(self) -> bool:
        """True for formats whose frames vary in size (MJPG)."""
        return self.layout is None

    def bytesperline(self, width: int) -> int:
        """V4L2 ``bytesperline`` (CSI-2 packed: 5 bytes per 4 10-bit pixels; 0 for compressed formats)."""
        return 0 if self.layout is None else self.layout.bytesperline(width)

    def sizeimage(self, width: int, height: int) -> int:
        """Buffer size a frame needs (for a compressed format a generous bound: the BGR frame's size)."""
        return (self.layout or _JPEG_BOUND).sizeimage(width, height)


FORMATS: dict[str, DeviceFormat] = {
    f: DeviceFormat(f, d, None if f in COMPRESSED else sf.pixel_format(f)) for f, d in _PROCESSED}
"""Formats the emulated ISP produces, in the order devices enumerate them."""


def raw_description(layout: sf.PixelFormat) -> str:
    """The kernel's style of name of a raw format: '10-bit Bayer RGRG/GBGB Packed', '10-bit Greyscale'."""
    kind = "Greyscale" if layout.cfa == "mono" else f"Bayer {layout.cfa[:2] * 2}/{layout.cfa[2:] * 2}"
    return f"{layout.bits}-bit {kind}{' Packed' if layout.packing == 'csi2' else ''}"


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


def device_format(fourcc: str) -> DeviceFormat:
    """The description of a processed or raw ``fourcc``; an unknown one is a ConfigError naming the known ones."""
    if fourcc in FORMATS:
        return FORMATS[fourcc]
    if is_raw(fourcc):
        layout = sf.pixel_format(fourcc)
        return DeviceFormat(layout.fourcc, raw_description(layout), layout, raw=True)
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
