"""DNG files of raw buffers, and buffers back into the arrays requests give.

DNG is written by pidng (MIT; picamera2's own DNG writer, installed with ``rollcam[picamera2]``) from the raw
stream's buffer as the receiver holds it (packed CSI-2 or 16-bit samples), with the frame's metadata: black
levels, colour gains, exposure and gain (as ISO). The stand-in's ISP has no colour correction matrix of its
own, so the DNG carries the identity (sRGB primaries), as raw developers need one.
"""

from __future__ import annotations

import io
import os
from typing import Any

import numpy as np
from rollcam.common.errors import require

from . import formats
from ._isp import stride_and_size
from .sensor_format import SensorFormat

IDENTITY_CCM = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)


def raw_stride(config: dict[str, Any]) -> int:
    """Bytes per line of a raw stream (its ``stride``, or what its format and width take without padding)."""
    if config.get("stride"):
        return int(config["stride"])
    fmt, width = SensorFormat(str(config["format"])), int(config["size"][0])
    if fmt.packing == "CSI2P":
        return -(-width * fmt.bit_depth // 8)
    return width * (2 if fmt.bit_depth > 8 else 1)


def buffer_array(buffer: np.ndarray, config: dict[str, Any]) -> np.ndarray:
    """A stream's 1-D buffer as the array ``make_array`` gives (raw: ``(height, stride)`` bytes)."""
    fmt, (w, h) = str(config["format"]), config["size"]
    flat = np.asarray(buffer).reshape(-1).view(np.uint8)
    if formats.is_raw(fmt):
        return flat[: raw_stride(config) * h].reshape(h, -1)
    stride, size = stride_and_size(fmt, (w, h))
    if formats.is_RGB(fmt):
        return flat[:size].reshape(h, w, stride // w)
    if fmt in ("YUYV", "YVYU", "UYVY", "VYUY"):
        return flat[:size].reshape(h, w, 2)
    return flat[:size].reshape(h * 3 // 2, w)


def write_dng(raw: np.ndarray, config: dict[str, Any], metadata: dict[str, Any], file_output: Any) -> None:
    """Write the raw stream's array (``(height, stride)`` bytes) as a DNG to a path or a writable object."""
    camdefs = require("pidng.camdefs", package="pidng", extra="picamera2", feature="DNG files")
    core = require("pidng.core", package="pidng", extra="picamera2", feature="DNG files")
    fmt = {"format": str(config["format"]), "size": tuple(config["size"]), "stride": raw_stride(config)}
    md = {"ColourCorrectionMatrix": IDENTITY_CCM, **metadata}
    writer = core.PICAM2DNG(camdefs.Picamera2Camera(fmt, md))
    writer.options(compress=False)
    data = writer.convert(np.ascontiguousarray(raw))
    if isinstance(file_output, (str, os.PathLike)):
        with open(file_output, "wb") as f:
            f.write(data)
    elif isinstance(file_output, io.IOBase) or hasattr(file_output, "write"):
        file_output.write(data)
    else:
        raise RuntimeError(f"Cannot save to {file_output!r}")
