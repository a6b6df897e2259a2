"""The ISP's last steps on its 8-bit picture, after demosaic and gamma: sharpening, then the encoder's JPEG.

They sit above both ``rollcam.sim.isp`` (the sharpening) and ``rollcam.sim.codecs`` (the one JPEG codec, which
itself runs raw previews through the ISP), so neither of those imports the other's way back.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from rollcam.common.errors import ConfigError

from .codecs import codec
from .isp import MAX_SHARPEN, sharpen


@dataclass(frozen=True)
class PictureSteps:
    """The ISP's last steps on its 8-bit picture, after demosaic and gamma: unsharp-mask sharpening of the luma
    by ``sharpen`` (0: off), then the camera encoder's JPEG compression at ``jpeg_quality`` (0: off; 1..100
    as libjpeg's quality scale), left in the picture as a decoder would see it. All off: no work."""

    sharpen: float = 0.0
    jpeg_quality: int = 0

    def __post_init__(self) -> None:
        if isinstance(self.sharpen, bool) or not isinstance(self.sharpen, (int, float)) \
                or not 0 <= self.sharpen <= MAX_SHARPEN:
            raise ConfigError(f"sharpen must be a number in 0..{MAX_SHARPEN:g}, got {self.sharpen!r}")
        if isinstance(self.jpeg_quality, bool) or not isinstance(self.jpeg_quality, (int, np.integer)) \
                or not 0 <= self.jpeg_quality <= 100:
            raise ConfigError(f"jpeg_quality must be a whole number in 0..100 (0: off), got {self.jpeg_quality!r}")

    @property
    def on(self) -> bool:
        """True when a step changes the picture."""
        return bool(self.sharpen or self.jpeg_quality)

    def info(self) -> dict[str, float]:
        """What a frame's metadata records about these steps (the ones that are on)."""
        return {k: v for k, v in (("sharpen", self.sharpen), ("jpeg_quality", self.jpeg_quality)) if v}

    def apply(self, bgr: np.ndarray) -> np.ndarray:
        """The 8-bit BGR picture after these steps (``bgr`` itself when all are off)."""
        if self.sharpen:
            bgr = sharpen(bgr, self.sharpen)
        if self.jpeg_quality:
            jpeg = codec("MJPG")
            bgr = jpeg.decode(jpeg.encode(bgr, quality=int(self.jpeg_quality)))
        return bgr
