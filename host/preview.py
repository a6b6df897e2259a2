"""Frames to 8-bit BGR previews (what OpenCV code and ``bgr`` detectors expect).

A frame's preview is its codec's (``rollcam.sim.codecs``): pictures decoded, raw Bayer or mono samples through
the preview ISP less the sensor's black level (from the frame's meta: the emulated sensor records it), so a
raw frame previews the same on the host as on every transport that shows it.
"""

from __future__ import annotations

import numpy as np
from rollcam.sim.codecs import preview_frame
from rollcam.sim.frame import Frame


def frame_bgr(frame: Frame) -> np.ndarray:
    """The frame's 8-bit BGR preview; a format without a codec is a ConfigError naming the supported ones."""
    return preview_frame(frame)
