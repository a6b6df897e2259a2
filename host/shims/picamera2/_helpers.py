"""``picam2.helpers``: buffers captured before (``capture_buffers``, ``switch_mode_and_capture_buffers``) to
arrays, PIL images and files, as picamera2's helpers do."""

from __future__ import annotations

from typing import Any

import numpy as np

from ._dng import buffer_array, write_dng
from .request import image_format, to_bgr


class Helpers:
    """``picam2.helpers``: ``make_array``, ``make_image``, ``save``, ``save_dng`` of buffers captured before."""

    def __init__(self, picam2: Any) -> None:
        self.picam2 = picam2

    def make_array(self, buffer: np.ndarray, config: dict[str, Any]) -> np.ndarray:
        """The array of a buffer of a stream with ``config``."""
        return buffer_array(buffer, config).copy()

    def make_image(self, buffer: np.ndarray, config: dict[str, Any], width: int | None = None,
                   height: int | None = None) -> Any:
        """A PIL image of a buffer of an RGB stream."""
        from PIL import Image

        bgr = to_bgr(buffer_array(buffer, config), str(config["format"]))
        img = Image.fromarray(np.ascontiguousarray(bgr[..., ::-1]))
        if (width, height) != (None, None):
            img = img.resize((width or img.size[0], height or img.size[1]))
        return img

    def save(self, img: Any, metadata: dict[str, Any], file_output: Any, format: str | None = None,
             exif_data: Any = None) -> None:
        """Save a PIL image (JPEG, PNG, ...) to a path or a file object."""
        ext = image_format(file_output, format)
        img.save(file_output, format={"jpg": "jpeg"}.get(ext, ext))

    def save_dng(self, buffer: np.ndarray, metadata: dict[str, Any], config: dict[str, Any],
                 file_output: Any) -> None:
        """Save a raw buffer as a DNG."""
        write_dng(buffer_array(buffer, config), config, metadata, file_output)
