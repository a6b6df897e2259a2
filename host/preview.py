"""Frames to 8-bit BGR previews (what OpenCV code and ``bgr`` detectors expect), by pixel format.

Table-driven over V4L2 fourccs: BGR3/RGB3/XR24 as they are, GREY and Y10/Y12/Y16 mono scaled to 8 bits, YUYV,
UYVY, NV12 and YU12 through OpenCV's colour conversions, MJPG decoded, and unpacked Bayer mosaics (8 bits, or
10/12/16 bits in uint16) demosaiced by OpenCV's bilinear method, a stand-in for an ISP. Bit-packed raw
formats (pRAA, Y10P, ...) need unpacking first and are refused with a message saying so.
"""

from __future__ import annotations

import cv2
import numpy as np
from rollcam.sim.errors import SourceError
from rollcam.sim.frame import Frame
from rollcam.sim.hwconfig import FOURCCS

DEMOSAIC = {"RGGB": cv2.COLOR_BayerBG2BGR, "BGGR": cv2.COLOR_BayerRG2BGR, "GRBG": cv2.COLOR_BayerGB2BGR,
            "GBRG": cv2.COLOR_BayerGR2BGR}
"""Bayer order of the mosaic's first 2x2 -> OpenCV demosaic code. OpenCV names a pattern by the second row's
second and third pixels, so an RGGB sensor is OpenCV's "BayerBG" (checked in tests)."""
YUV = {"YUYV": cv2.COLOR_YUV2BGR_YUYV, "UYVY": cv2.COLOR_YUV2BGR_UYVY, "NV12": cv2.COLOR_YUV2BGR_NV12,
       "YU12": cv2.COLOR_YUV2BGR_I420}
PACKED = {"pRAA", "pBAA", "pgAA", "pGAA", "pRCC", "pBCC", "pgCC", "pGCC", "Y10P"}


def _to8(data: np.ndarray, bits: int) -> np.ndarray:
    if data.dtype == np.uint8:
        return data
    return np.clip(data >> max(bits - 8, 0), 0, 255).astype(np.uint8)


def to_bgr(data: np.ndarray, fmt: str) -> np.ndarray:
    """Pixel data of fourcc ``fmt`` as an 8-bit BGR image (H x W x 3)."""
    if fmt == "BGR3":
        return data
    if fmt == "RGB3":
        return np.ascontiguousarray(data[..., ::-1])
    if fmt == "XR24":
        return np.ascontiguousarray(data[..., :3])
    if fmt in YUV:
        return cv2.cvtColor(data, YUV[fmt])
    if fmt == "MJPG":
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        if img is None:
            raise SourceError("an MJPG frame could not be decoded")
        return img
    if fmt in PACKED:
        raise SourceError(f"pixel format {fmt!r} is bit-packed; unpack it to 16 bits first (e.g. RG10 for pRAA)")
    order, bits = FOURCCS.get(fmt, (None, 8))
    if order in DEMOSAIC:
        return cv2.cvtColor(_to8(data, bits), DEMOSAIC[order])
    if order == "mono" or fmt == "GREY":
        return cv2.cvtColor(_to8(data.reshape(data.shape[:2]), bits), cv2.COLOR_GRAY2BGR)
    raise SourceError(f"pixel format {fmt!r} (data {data.shape} {data.dtype}) has no BGR preview conversion")


def frame_bgr(frame: Frame) -> np.ndarray:
    """The frame's 8-bit BGR preview."""
    return to_bgr(frame.data, frame.format)
