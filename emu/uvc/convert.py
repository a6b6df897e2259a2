"""Pixel conversion between the renderer's BGR frames and the UVC wire formats (YUYV, NV12, MJPEG), via OpenCV.

The one place the UVC code converts pixels: ``encode`` on the device side, ``decode`` on the host side.
"""

from __future__ import annotations

import cv2
import numpy as np
from rollcam.sim.errors import ProtocolError

WIRE_FORMATS = ("YUYV", "NV12", "MJPG")


def frame_size(fourcc: str, width: int, height: int) -> int | None:
    """Bytes of one uncompressed frame (None for MJPEG, whose size varies)."""
    return {"YUYV": width * height * 2, "NV12": width * height * 3 // 2}.get(fourcc)


def encode(bgr: np.ndarray, fourcc: str, jpeg_quality: int = 85) -> np.ndarray:
    """A BGR image (H, W, 3 uint8) as the bytes of ``fourcc`` (a flat uint8 array)."""
    if bgr.dtype != np.uint8:
        bgr = np.clip(bgr, 0, 255).astype(np.uint8)
    if bgr.ndim == 2:
        bgr = cv2.cvtColor(bgr, cv2.COLOR_GRAY2BGR)
    if fourcc == "YUYV":
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2YUV_YUY2).reshape(-1)  # OpenCV >= 4.7
    if fourcc == "NV12":
        i420 = cv2.cvtColor(bgr, cv2.COLOR_BGR2YUV_I420).reshape(-1)
        h, w = bgr.shape[:2]
        n = h * w
        q = n // 4
        out = np.empty(n * 3 // 2, np.uint8)
        out[:n] = i420[:n]
        out[n::2] = i420[n:n + q]
        out[n + 1::2] = i420[n + q:n + 2 * q]
        return out
    if fourcc == "MJPG":
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
        if not ok:
            raise ProtocolError(f"JPEG encoding of a {bgr.shape} frame failed")
        return buf.reshape(-1)
    raise ProtocolError(f"wire format {fourcc!r} is not one of {WIRE_FORMATS}")


def decode(data: bytes, fourcc: str, width: int, height: int) -> np.ndarray:
    """The bytes of one ``fourcc`` frame as a BGR image; wrong sizes and undecodable JPEG raise ProtocolError."""
    raw = np.frombuffer(data, np.uint8)
    need = frame_size(fourcc, width, height)
    if need is not None and raw.size != need:
        raise ProtocolError(f"{fourcc} {width}x{height} frame needs {need} bytes, got {raw.size}")
    if fourcc == "YUYV":
        return cv2.cvtColor(raw.reshape(height, width, 2), cv2.COLOR_YUV2BGR_YUYV)
    if fourcc == "NV12":
        return cv2.cvtColor(raw.reshape(height * 3 // 2, width), cv2.COLOR_YUV2BGR_NV12)
    if fourcc == "MJPG":
        img = cv2.imdecode(raw, cv2.IMREAD_COLOR) if raw.size else None
        if img is None:
            raise ProtocolError(f"MJPEG frame of {raw.size} bytes does not decode")
        return img
    raise ProtocolError(f"wire format {fourcc!r} is not one of {WIRE_FORMATS}")
