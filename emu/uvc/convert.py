"""The UVC wire formats (YUYV, NV12, MJPEG): which fourccs UVC carries, through the codec table.

``encode`` on the device side and ``decode`` on the host side are the rows of ``rollcam.sim.codecs`` for
these fourccs, with the UVC code's error: anything else, and wrong sizes or undecodable JPEG, raise
ProtocolError. Layouts and sizes (``wire_layout``) are ``rollcam.sim.formats``'s.
"""

from __future__ import annotations

import numpy as np
from rollcam.common.errors import ConfigError, ProtocolError
from rollcam.sim.codecs import JPEG_QUALITY, Codec, codec
from rollcam.sim.formats import PixelFormat

WIRE_FORMATS = ("YUYV", "NV12", "MJPG")


def _wire(fourcc: str) -> Codec:
    if fourcc not in WIRE_FORMATS:
        raise ProtocolError(f"wire format {fourcc!r} is not one of {WIRE_FORMATS}")
    return codec(fourcc)


def wire_layout(fourcc: str) -> PixelFormat | None:
    """The ``rollcam.sim.formats`` layout (sizeimage, shape) of an uncompressed wire format; None for MJPEG,
    whose frames vary in size."""
    return _wire(fourcc).layout


def encode(bgr: np.ndarray, fourcc: str, jpeg_quality: int = JPEG_QUALITY) -> np.ndarray:
    """A BGR image (H, W, 3 uint8) as the bytes of ``fourcc`` (a flat uint8 array)."""
    c = _wire(fourcc)
    try:
        return c.encode(bgr, quality=jpeg_quality).reshape(-1)
    except ConfigError as exc:
        raise ProtocolError(f"cannot encode a {np.shape(bgr)} frame as {fourcc}: {exc}") from None


def decode(data: bytes, fourcc: str, width: int, height: int) -> np.ndarray:
    """The bytes of one ``fourcc`` frame as a BGR image; wrong sizes and undecodable JPEG raise ProtocolError."""
    return _wire(fourcc).decode(data, width, height)
