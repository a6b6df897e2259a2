"""The firmware camera's output formats: the emulated ISP's processed ones and the sensor's raw ones.

``FORMATS`` are the processed formats, made from BGR renders by the codec table (``rollcam.sim.codecs``,
which every transport converts pixels with). A sensor's raw fourccs (Bayer or mono samples, unpacked or
CSI-2 packed, from its hw_config ``formats``) bypass the ISP, as on a near-sensor camera. ``device_format``
describes either kind to devices as a ``DeviceFormat`` (the V4L2 description; layout, bytesperline and
sizeimage are ``rollcam.sim.formats``'s, MJPG being the one compressed format).
"""

from __future__ import annotations

from dataclasses import dataclass

from rollcam.common.errors import ConfigError
from rollcam.sim import formats as sf
from rollcam.sim.hwconfig import SensorConfig

_PROCESSED = (  # the emulated ISP's formats, in the order devices enumerate them, with V4L2's descriptions
    ("YUYV", "YUYV 4:2:2"),
    ("BGR3", "24-bit BGR 8-8-8"),
    ("RGB3", "24-bit RGB 8-8-8"),
    ("GREY", "8-bit Greyscale"),
    ("MJPG", "Motion-JPEG"),
    ("UYVY", "UYVY 4:2:2"),
    ("NV12", "Y/CbCr 4:2:0"),  # the name before Linux 6.2, which v4l2-compliance of every version accepts
    ("YU12", "Planar YUV 4:2:0"),
    ("XR24", "32-bit BGRX 8-8-8-8"),
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
    if layout.cfa == "mono":  # videodev2's names: "10-bit Greyscale (MIPI Packed)", "10-bit Greyscale"
        return f"{layout.bits}-bit Greyscale{' (MIPI Packed)' if layout.packing == 'csi2' else ''}"
    kind = f"Bayer {layout.cfa[:2] * 2}/{layout.cfa[2:] * 2}"
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
