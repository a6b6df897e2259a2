"""Completed requests: one frame's stream arrays and metadata, held until released (picamera2's API).

A ``CompletedRequest`` owns one buffer of the camera's ``buffer_count``: while the application holds it the
camera has one buffer fewer, and when every buffer is held the sensor's frames are dropped, as a Pi drops
frames when no request is queued. ``release()`` gives it back (it is reference counted, as picamera2's is).
``MappedArray(request, "main")`` is the stream's array itself, writable (overlays before an encoder, in
``pre_callback``); ``make_array`` copies it.
"""

from __future__ import annotations

import io
import os
import struct
import threading
from collections.abc import Callable
from typing import Any

import numpy as np
from rollcam.common.errors import require

from . import formats
from ._dng import write_dng
from ._isp import RGB_LAYOUTS, YUV_CODECS


class CompletedRequest:
    """One frame: ``make_array(name)``, ``make_buffer``, ``make_image``, ``get_metadata``, ``save``,
    ``release`` (or ``with request:``)."""

    def __init__(self, arrays: dict[str, np.ndarray], metadata: dict[str, Any], config: dict[str, Any],
                 picam2: Any, on_release: Callable[[CompletedRequest], None]) -> None:
        self.arrays, self.metadata = arrays, metadata
        self.config = config
        self.picam2 = picam2
        self.ref_count = 1
        self._lock = threading.Lock()
        self._on_release = on_release

    def __repr__(self) -> str:
        return (f"<CompletedRequest seq={self.metadata.get('RollcamSequence')} "
                f"t={self.metadata.get('SensorTimestamp')} streams={sorted(self.arrays)} refs={self.ref_count}>")

    def __enter__(self) -> CompletedRequest:
        return self

    @property
    def stream_map(self) -> dict[str, Any]:
        """The camera's streams as libcamera describes them (``stream_map["main"].configuration.size``)."""
        return self.picam2.stream_map

    def __exit__(self, *exc: object) -> None:
        self.release()

    def acquire(self) -> None:
        """Take one more reference (the request is released when every one is)."""
        with self._lock:
            if self.ref_count == 0:
                raise RuntimeError("CompletedRequest: acquiring lock with ref_count 0")
            self.ref_count += 1

    def release(self) -> None:
        """Give back one reference; the last one returns the buffer to the camera."""
        with self._lock:
            self.ref_count -= 1
            if self.ref_count < 0:
                raise RuntimeError("CompletedRequest: lock now has negative ref_count")
            last = self.ref_count == 0
        if last:
            self._on_release(self)

    def _array(self, name: str) -> np.ndarray:
        if self.ref_count <= 0:
            raise RuntimeError("CompletedRequest: used after release")
        if name not in self.arrays:
            raise RuntimeError(f"Stream {name!r} is not defined")
        return self.arrays[name]

    def make_array(self, name: str) -> np.ndarray:
        """A copy of the named stream's image (shape per format: (h, w, 3|4) RGB, (h*3/2, w) YUV420,
        (h, stride) uint8 raw)."""
        return np.copy(self._array(name))

    def make_buffer(self, name: str) -> np.ndarray:
        """A copy of the named stream's buffer as 1-D bytes."""
        return np.copy(self._array(name)).reshape(-1).view(np.uint8)

    def get_metadata(self) -> dict[str, Any]:
        """The frame's metadata (a copy)."""
        return dict(self.metadata)

    def make_image(self, name: str, width: int | None = None, height: int | None = None) -> Any:
        """A PIL image of an RGB stream (optionally resized)."""
        from PIL import Image

        fmt = self.config[name]["format"] if name in self.arrays else None
        if fmt not in RGB_LAYOUTS:
            raise RuntimeError(f"Stream format {fmt} not supported for PIL images")
        img = Image.fromarray(np.ascontiguousarray(to_bgr(self._array(name), fmt)[..., ::-1]))
        w, h = img.size
        if (width or w, height or h) != (w, h):
            img = img.resize((width or w, height or h))
        return img

    def save(self, name: str, file_output: Any, format: str | None = None,
             exif_data: dict[str, Any] | None = None) -> None:
        """Save the named stream as JPEG or PNG (any format OpenCV writes), to a path or a file object."""
        fmt = self.config[name]["format"] if name in self.arrays else None
        if fmt is None:
            raise RuntimeError(f"Stream {name!r} is not defined")
        if formats.is_raw(fmt):
            write_dng(self._array(name), self.config[name], self.metadata, file_output)
            return
        ext = image_format(file_output, format)
        quality = int(getattr(self.picam2, "options", {}).get("quality", 90))
        exif = None
        if exif_data and ext in ("jpg", "jpeg"):
            piexif = require("piexif", extra="picamera2", feature="picamera2's exif_data")
            exif = piexif.dump(exif_data)
        write_image(file_output, to_bgr(self._array(name), fmt), ext, quality, exif)

    def save_dng(self, file_output: Any, name: str = "raw") -> None:
        """Save the raw stream as a DNG (pidng) to a path or a file object."""
        if name not in self.arrays:
            raise RuntimeError(f"Stream {name!r} is not defined")
        write_dng(self._array(name), self.config[name], self.metadata, file_output)


class MappedArray:
    """``with MappedArray(request, "main") as m: m.array`` is the stream's array itself (writes show in
    everything that reads the request later)."""

    def __init__(self, request: CompletedRequest, stream: str, reshape: bool = True, write: bool = True) -> None:
        self._request, self._stream, self._reshape = request, stream, reshape
        self.array: np.ndarray | None = None

    def __enter__(self) -> MappedArray:
        a = self._request._array(self._stream)
        self.array = a if self._reshape else a.reshape(-1).view(np.uint8)
        return self

    def __exit__(self, *exc: object) -> None:
        self.array = None


def to_bgr(array: np.ndarray, fmt: str) -> np.ndarray:
    """A processed stream's array as an 8-bit BGR picture (for files and PIL)."""
    from rollcam.sim.codecs import codec

    if fmt in RGB_LAYOUTS:
        order, _ = RGB_LAYOUTS[fmt]
        img = array[..., :3]
        return np.ascontiguousarray(img if order == "bgr" else img[..., ::-1])
    if fmt in ("YUV420", "NV12", "YUYV", "UYVY"):
        h = array.shape[0] * 2 // 3 if fmt in ("YUV420", "NV12") else array.shape[0]
        return codec(YUV_CODECS[fmt]).decode(array, array.shape[1], h)
    raise RuntimeError(f"Stream format {fmt} cannot be saved as an image")


def image_format(file_output: Any, format: str | None) -> str:
    """The file format to write: ``format``, else the path's extension (lower case, no dot)."""
    if isinstance(format, str):
        return format.lower().lstrip(".")
    if isinstance(file_output, (str, os.PathLike)):
        return os.fspath(file_output).rsplit(".", 1)[-1].lower()
    raise RuntimeError("Cannot determine format to save")


def write_image(file_output: Any, bgr: np.ndarray, ext: str, quality: int = 90, exif: bytes | None = None) -> None:
    """Encode a BGR picture (``ext``: jpg/jpeg through the codec table's one JPEG encoder, with an EXIF
    block ``exif`` (``Exif\\0\\0`` and a TIFF structure, as ``piexif.dump`` makes) when given; png, bmp, ...
    with OpenCV) to a path (atomically) or a writable file object."""
    from rollcam.common.files import write_atomic
    from rollcam.sim.codecs import codec, encode_image

    if ext in ("jpg", "jpeg"):
        data = codec("MJPG").encode(bgr, quality=quality).tobytes()
        if exif:  # an APP1 segment right after the start-of-image marker
            data = data[:2] + b"\xff\xe1" + struct.pack(">H", len(exif) + 2) + exif + data[2:]
    else:
        data = encode_image(bgr, ext, error=RuntimeError, what="the image")
    if isinstance(file_output, (str, os.PathLike)):
        write_atomic(file_output, data)
    elif isinstance(file_output, io.IOBase) or hasattr(file_output, "write"):
        file_output.write(data)
    else:
        raise RuntimeError(f"Cannot save to {file_output!r}")
