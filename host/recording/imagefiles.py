"""Frames as image files: the picture or lossless sample layout each image format stores, and its bytes.

Shared by ``rollcam capture``, the dataset builder and the robotics recordings (which put the same pictures
into ROS messages), so every door stores a frame's pixels the same way.
"""

from __future__ import annotations

import numpy as np
from rollcam.common.errors import ConfigError, SourceError
from rollcam.sim.codecs import codec
from rollcam.sim.codecs import encode_image as encode_file
from rollcam.sim.formats import FORMATS
from rollcam.sim.frame import Frame

_PICTURES = ("BGR3", "RGB3", "GREY")


def image_array(frame: Frame, fmt: str) -> np.ndarray:
    """Pixel data in the layout an image file of format ``fmt`` stores (as OpenCV writes it).

    BGR3/RGB3 become BGR pictures, GREY a grey one. Any other format (raw Bayer or mono, CSI-2 packed,
    YUYV, NV12) is stored losslessly as its memory layout in 2-D: rows by bytes (uint8) or by samples
    (uint16, 16-bit PNG), so ``frames.jsonl``'s format, width, height and bytesperline restore the frame.
    JPEG would lose samples, so it takes only the picture formats.
    """
    data = frame.data
    if frame.format in _PICTURES or frame.format not in FORMATS:
        if data.ndim == 3 and data.shape[2] == 3:
            img = codec("RGB3").decode(data, frame.width, frame.height) if frame.format == "RGB3" else data
        elif data.ndim == 2 or (data.ndim == 3 and data.shape[2] == 1):
            img = data
        else:
            raise SourceError(f"frame {frame.sequence} ({frame.format}, shape {data.shape}) cannot be stored as an "
                              "image file; capture needs BGR3, RGB3 or single-channel frames")
        if img.dtype != np.uint8 and not (img.dtype == np.uint16 and fmt == "png"):
            raise ConfigError(f"--format {fmt} cannot hold {frame.format} frames of dtype {img.dtype}"
                              + ("; use --format png" if img.dtype == np.uint16 else ""))
        return img
    if fmt == "jpg":
        raise ConfigError(f"--format jpg would lose the samples of {frame.format!r} frames; use png or npy")
    if data.dtype not in (np.uint8, np.uint16):
        raise SourceError(f"frame {frame.sequence} ({frame.format}) has dtype {data.dtype}, not uint8/uint16")
    return data.reshape(data.shape[0], -1)


def encode_image(frame: Frame, fmt: str) -> bytes:
    """The frame as PNG or JPEG bytes, or its data array exactly as ``.npy``."""
    if fmt == "npy":
        import io

        buf = io.BytesIO()
        np.save(buf, np.ascontiguousarray(frame.data), allow_pickle=False)
        return buf.getvalue()
    return encode_file(image_array(frame, fmt), fmt, error=SourceError, what=f"frame {frame.sequence}")
