"""Which ``Picamera2`` holds each camera number: the stand-in's libcamera acquire, read by the camera and by the
IMX500's network loader and tensor injection (``_cnn``)."""

from __future__ import annotations

import threading
from typing import Any

OPEN: dict[int, Any] = {}
"""Camera number -> the ``Picamera2`` holding it; guarded by ``OPEN_LOCK``."""
OPEN_LOCK = threading.Lock()
