"""``JpegEncoder`` and ``MJPEGEncoder``: each frame a JPEG, by rollcam's one JPEG encoder (``sim.codecs``),
as picamera2's JpegEncoder encodes in software (the Pi's MJPEGEncoder uses the hardware encoder)."""

from __future__ import annotations

from typing import Any

from rollcam.sim.codecs import codec

from ..request import to_bgr
from .encoder import Encoder, Quality

_JPEG_QUALITY = {Quality.VERY_LOW: 25, Quality.LOW: 45, Quality.MEDIUM: 70, Quality.HIGH: 85, Quality.VERY_HIGH: 95}


class JpegEncoder(Encoder):
    """Motion JPEG: every frame a keyframe, at JPEG quality ``q`` (or the Quality's)."""

    codec = "mjpeg"

    def __init__(self, num_threads: int = 4, q: int | None = None, colour_space: Any = None,
                 colour_subsampling: str = "420") -> None:
        super().__init__()
        self.num_threads, self.q, self.colour_subsampling = num_threads, q, colour_subsampling
        self._quality = q if q is not None else _JPEG_QUALITY[Quality.MEDIUM]

    def _setup(self, quality: Quality | None) -> None:
        if self.q is None and quality is not None:
            self._quality = _JPEG_QUALITY[quality]

    def _encode(self, array: Any, timestamp_us: int) -> None:
        data = codec("MJPG").encode(to_bgr(array, self.format or ""), quality=self._quality).tobytes()
        self.outputframe(data, keyframe=True, timestamp=timestamp_us)


class MJPEGEncoder(JpegEncoder):
    """picamera2's MJPEG encoder (``bitrate`` is taken but the quality decides the size)."""

    def __init__(self, bitrate: int | None = None) -> None:
        super().__init__()
        self.bitrate = bitrate


LibavMjpegEncoder = MJPEGEncoder
