"""Pixel conversion between the renderer's BGR frames and the UVC wire formats (YUYV, NV12, MJPEG).

The one place the UVC code converts pixels: ``encode`` on the device side, ``decode`` on the host side;
the layouts and sizes come from ``rollcam.sim.formats`` (``wire_layout``) and JPEG from ``rollcam.firmware.pixfmt``.
"""

from __future__ import annotations

import cv2
import numpy as np
from rollcam.common.errors import ConfigError, ProtocolError
from rollcam.firmware.pixfmt import encode_jpeg
from rollcam.sim.formats import PixelFormat, bgr_to_nv12, bgr_to_yuyv, nv12_to_bgr, pixel_format, yuyv_to_bgr

WIRE_FORMATS = ("YUYV", "NV12", "MJPG")


def wire_layout(fourcc: str) -> PixelFormat | None:
    """The ``rollcam.sim.formats`` layout (sizeimage, shape) of an uncompressed wire format; None for MJPEG,
    whose frames vary in size."""
    if fourcc not in WIRE_FORMATS:
        raise ProtocolError(f"wire format {fourcc!r} is not one of {WIRE_FORMATS}")
    return None if fourcc == "MJPG" else pixel_format(fourcc)


def encode(bgr: np.ndarray, fourcc: str, jpeg_quality: int = 85) -> np.ndarray:
    """A BGR image (H, W, 3 uint8) as the bytes of ``fourcc`` (a flat uint8 array)."""
    if bgr.dtype != np.uint8:
        bgr = np.clip(bgr, 0, 255).astype(np.uint8)
    if bgr.ndim == 2:
        bgr = cv2.cvtColor(bgr, cv2.COLOR_GRAY2BGR)
    try:
        if fourcc == "YUYV":
            return bgr_to_yuyv(bgr).reshape(-1)
        if fourcc == "NV12":
            return bgr_to_nv12(bgr).reshape(-1)
        if fourcc == "MJPG":
            return np.frombuffer(encode_jpeg(bgr, jpeg_quality), np.uint8)
    except ConfigError as exc:
        raise ProtocolError(f"cannot encode a {bgr.shape} frame as {fourcc}: {exc}") from None
    raise ProtocolError(f"wire format {fourcc!r} is not one of {WIRE_FORMATS}")


_TO_BGR = {"YUYV": yuyv_to_bgr, "NV12": nv12_to_bgr}


def decode(data: bytes, fourcc: str, width: int, height: int) -> np.ndarray:
    """The bytes of one ``fourcc`` frame as a BGR image; wrong sizes and undecodable JPEG raise ProtocolError."""
    raw = np.frombuffer(data, np.uint8)
    layout = wire_layout(fourcc)
    if layout is None:
        img = cv2.imdecode(raw, cv2.IMREAD_COLOR) if raw.size else None
        if img is None:
            raise ProtocolError(f"MJPEG frame of {raw.size} bytes does not decode")
        return img
    need = layout.sizeimage(width, height)
    if raw.size != need:
        raise ProtocolError(f"{fourcc} {width}x{height} frame needs {need} bytes, got {raw.size}")
    return _TO_BGR[fourcc](raw.reshape(layout.shape(width, height)))
