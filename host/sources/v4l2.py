"""``v4l2:/dev/videoN[?sensor=..&size=..&fps=..&exposure=..&gain=..&fourcc=..]`` -- a Linux V4L2 camera.

Opened through OpenCV's V4L2 backend (``CAP_V4L2``); options and controls are those of ``opencv:``
(``rollcam.host.sources.opencv``). ``sensor=NAME`` gives the frames that sensor's row timing. Linux only.
"""

from __future__ import annotations

import os
import sys

import cv2
from rollcam.common.errors import DeviceError, DeviceNotFoundError, SourceError

from .base import SourceURI
from .opencv import OpenCVSource


def open_source(uri: SourceURI) -> OpenCVSource:
    """Scheme entry point for ``v4l2:``."""
    if not sys.platform.startswith("linux"):
        raise SourceError(f"source {uri.uri!r}: V4L2 exists only on Linux; use opencv:N on {sys.platform}")
    path = uri.target or "/dev/video0"
    if path.isdigit():
        path = f"/dev/video{path}"
    if not os.path.exists(path):
        raise DeviceNotFoundError(f"source {uri.uri!r}: no device {path!r}; plug in a camera (or load its driver) "
                                  "and check 'rollcam list' or 'ls /dev/video*'")
    if not os.access(path, os.R_OK | os.W_OK):
        raise DeviceError(f"source {uri.uri!r}: no permission to open {path!r}; add yourself to the 'video' group")
    return OpenCVSource(uri, path, cv2.CAP_V4L2, hint=" (is it a capture device and not busy?)")
