"""A small preview ISP: raw Bayer or mono samples -> 8-bit BGR.

Steps, in the order a camera ISP runs them: black-level subtraction, normalisation to the sensor's white
level, white balance (fixed gains or grey-world), demosaic (OpenCV's bilinear or edge-aware), sRGB gamma.
It is a preview, for detectors that want RGB: the ISP-less path hands raw frames straight to the consumer.
``rollcam.sim.codecs`` runs every raw preview through ``preview`` and makes the processed fourccs from its output.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from rollcam.common.errors import ConfigError

_DEMOSAIC = {  # Bayer order -> OpenCV code (OpenCV names the tile by its second row: RGGB is 'BayerBG')
    "RGGB": "BG", "BGGR": "RG", "GRBG": "GB", "GBRG": "GR",
}
_DEMOSAIC_ALGOS = {"bilinear": "", "ea": "_EA", "vng": "_VNG"}


@dataclass(frozen=True)
class IspParams:
    """Preview ISP settings. ``wb_gains`` (R, G, B) None = grey-world; ``gamma`` None = linear output."""

    black_level_dn: float = 0.0
    white_level_dn: float = 1023.0
    wb_gains: tuple[float, float, float] | None = (1.0, 1.0, 1.0)
    demosaic: str = "bilinear"
    gamma: str | None = "srgb"

    def __post_init__(self) -> None:
        if self.white_level_dn <= self.black_level_dn:
            raise ConfigError(f"white level {self.white_level_dn!r} must exceed black level "
                              f"{self.black_level_dn!r}")
        if self.demosaic not in _DEMOSAIC_ALGOS:
            raise ConfigError(f"demosaic {self.demosaic!r} is not one of {list(_DEMOSAIC_ALGOS)}")
        if self.gamma not in (None, "srgb"):
            raise ConfigError(f"gamma {self.gamma!r} is not 'srgb' or None")


def _srgb_lut(n: int) -> np.ndarray:
    v = np.linspace(0.0, 1.0, n)
    s = np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(v, 1 / 2.4) - 0.055)
    return np.clip(np.round(s * 255.0), 0, 255).astype(np.uint8)


_LUT_BITS = 12
_SRGB = _srgb_lut(1 << _LUT_BITS)


def demosaic(raw: np.ndarray, order: str, algo: str = "bilinear") -> np.ndarray:
    """Bayer samples (uint8 or uint16 (H, W)) -> BGR of the same dtype, with OpenCV; mono is replicated."""
    import cv2

    if order == "mono":
        return np.repeat(raw[..., None], 3, axis=2)
    if order not in _DEMOSAIC:
        raise ConfigError(f"Bayer order {order!r} is not one of {list(_DEMOSAIC)} or 'mono'")
    if algo == "vng" and raw.dtype != np.uint8:
        raise ConfigError("OpenCV's VNG demosaic takes 8-bit input only; use 'bilinear' or 'ea'")
    code = getattr(cv2, f"COLOR_Bayer{_DEMOSAIC[order]}2BGR{_DEMOSAIC_ALGOS[algo]}")
    return cv2.cvtColor(np.ascontiguousarray(raw), code)


def preview(raw: np.ndarray, order: str, params: IspParams) -> np.ndarray:
    """Raw samples ``(H, W)`` of a sensor with CFA ``order`` -> 8-bit BGR through the preview ISP."""
    rgb = demosaic(raw, order, params.demosaic).astype(np.float32)
    span = params.white_level_dn - params.black_level_dn
    lin = (rgb - np.float32(params.black_level_dn)) * np.float32(1.0 / span)
    if order != "mono":
        gains = params.wb_gains
        if gains is None:  # grey world: equalise channel means to green's
            m = lin.reshape(-1, 3).mean(axis=0)
            gains = (m[1] / max(m[2], 1e-6), 1.0, m[1] / max(m[0], 1e-6))
        lin *= np.array([gains[2], gains[1], gains[0]], np.float32)  # BGR order
    np.clip(lin, 0.0, 1.0, out=lin)
    if params.gamma is None:
        return np.round(lin * 255.0).astype(np.uint8)
    idx = (lin * ((1 << _LUT_BITS) - 1) + 0.5).astype(np.int32)
    return _SRGB[idx]
