"""Frames to 8-bit BGR previews (what OpenCV code and ``bgr`` detectors expect), by pixel format.

Every fourcc of ``rollcam.sim.formats`` is decoded there (CSI-2 packed raw is unpacked, YUYV/NV12/YU12 go
through OpenCV's colour conversions); raw Bayer and mono samples are scaled to 8 bits and demosaiced with
``rollcam.sim.isp.demosaic`` (OpenCV bilinear), a stand-in for an ISP. A few formats real cameras send that
the emulator does not make (UYVY, XR24, MJPG) are handled here too.
"""

from __future__ import annotations

import cv2
import numpy as np
from rollcam.common.errors import ConfigError, SourceError
from rollcam.sim.formats import decode_raw, nv12_to_bgr, pixel_format, yu12_to_bgr, yuyv_to_bgr
from rollcam.sim.frame import Frame
from rollcam.sim.isp import demosaic

_PROCESSED = {"bgr": lambda d: d, "rgb": lambda d: np.ascontiguousarray(d[..., ::-1]), "yuyv": yuyv_to_bgr,
              "nv12": nv12_to_bgr, "yu12": yu12_to_bgr}
_FOREIGN = {"UYVY": lambda d: cv2.cvtColor(d, cv2.COLOR_YUV2BGR_UYVY),
            "XR24": lambda d: np.ascontiguousarray(d[..., :3])}


def _mjpg(data: np.ndarray) -> np.ndarray:
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        raise SourceError("an MJPG frame could not be decoded")
    return img


def to_bgr(data: np.ndarray, fmt: str, width: int | None = None) -> np.ndarray:
    """Pixel data of fourcc ``fmt`` as an 8-bit BGR image (H x W x 3); ``width`` helps unpack CSI-2 rows."""
    if fmt == "MJPG":
        return _mjpg(data)
    if fmt in _FOREIGN:
        return _FOREIGN[fmt](data)
    try:
        f = pixel_format(fmt)
    except ConfigError:
        raise SourceError(f"pixel format {fmt!r} (data {data.shape} {data.dtype}) has no BGR preview "
                          "conversion") from None
    if not f.is_raw:
        return _PROCESSED[f.packing](data)
    if f.packing == "csi2" and width is None and (data.ndim != 2 or (data.shape[1] * 8) % f.bits):
        raise SourceError(f"pixel format {fmt!r} is bit-packed and its width is unknown ({data.shape})")
    samples = decode_raw(data, f.fourcc, width).reshape(data.shape[0], -1)
    eight = samples if samples.dtype == np.uint8 else (samples >> max(f.bits - 8, 0)).astype(np.uint8)
    return demosaic(eight, f.cfa)


def frame_bgr(frame: Frame) -> np.ndarray:
    """The frame's 8-bit BGR preview."""
    return to_bgr(frame.data, frame.format, frame.width)
