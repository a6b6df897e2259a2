"""A small preview ISP: raw Bayer or mono samples -> 8-bit BGR.

Steps, in the order a camera ISP runs them: black-level subtraction, normalisation to the sensor's white
level, white balance (fixed gains or grey-world), demosaic (OpenCV's bilinear or edge-aware), sRGB gamma.
It is a preview, for detectors that want RGB: the ISP-less path hands raw frames straight to the consumer.
After the demosaic every step is a function of one channel's integer sample, so ``preview`` applies them as
a lookup table per channel (built with the same float32 arithmetic, so the output is the same bit for bit as
running the steps on every pixel, at a fraction of the cost: no frame-sized float arrays).
``rollcam.sim.codecs`` runs every raw preview through ``preview`` and makes the processed fourccs from its output.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange
from rollcam.common.errors import ConfigError

from ._jitcache import guard

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
    rgb = demosaic(raw, order, params.demosaic)
    gains = (1.0, 1.0, 1.0)
    if order != "mono":
        gains = params.wb_gains
        if gains is None:  # grey world: equalise channel means to green's
            span = params.white_level_dn - params.black_level_dn
            m = (rgb.reshape(-1, 3).mean(axis=0, dtype=np.float64) - params.black_level_dn) / span
            gains = (m[1] / max(m[2], 1e-6), 1.0, m[1] / max(m[0], 1e-6))
    lut = tone_lut(int(np.iinfo(rgb.dtype).max) + 1, params, (float(gains[0]), float(gains[1]), float(gains[2])))
    out = np.empty(rgb.shape, np.uint8)
    _apply_lut(rgb.reshape(-1, 3), lut, out.reshape(-1, 3))
    return out


_LUTS: dict[tuple, np.ndarray] = {}


def tone_lut(n: int, params: IspParams, gains: tuple[float, float, float]) -> np.ndarray:
    """uint8 ``(3, n)``: the BGR output of each channel's sample value 0 .. n - 1 (black and white levels,
    white balance ``gains`` (R, G, B), clip, gamma), in the float32 steps of the per-pixel definition."""
    key = (n, params, gains)
    lut = _LUTS.get(key)
    if lut is None:
        span = params.white_level_dn - params.black_level_dn
        v = np.arange(n, dtype=np.float32)
        lin = (v - np.float32(params.black_level_dn)) * np.float32(1.0 / span)
        lin = lin[None, :] * np.array([gains[2], gains[1], gains[0]], np.float32)[:, None]  # BGR order
        np.clip(lin, 0.0, 1.0, out=lin)
        if params.gamma is None:
            lut = np.round(lin * 255.0).astype(np.uint8)
        else:
            lut = _SRGB[(lin * ((1 << _LUT_BITS) - 1) + 0.5).astype(np.int32)]
        if len(_LUTS) >= 8:  # a stream has one; keep a few
            _LUTS.pop(next(iter(_LUTS)))
        _LUTS[key] = lut
    return lut


MAX_SHARPEN = 4.0
"""Largest unsharp-mask amount (a phone ISP's default is about 0.5..1.5; beyond 4 every edge rings)."""
SHARPEN_SIGMA_PX = 1.0
"""Radius (Gaussian sigma, px) of the unsharp mask's blur: the detail band a camera ISP boosts."""


def sharpen(bgr: np.ndarray, amount: float, sigma_px: float = SHARPEN_SIGMA_PX) -> np.ndarray:
    """Unsharp mask on the luma: every channel plus ``amount`` x (Y - Gaussian(Y, ``sigma_px``)), BT.601 Y,
    rounded and clipped to 8 bits. Luma only, as camera ISPs do, so edges gain contrast without colour
    fringes."""
    import cv2

    img = np.ascontiguousarray(bgr)
    y = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY).astype(np.float32)
    low = cv2.GaussianBlur(y, (0, 0), sigma_px, borderType=cv2.BORDER_REFLECT)
    out = np.empty_like(img)
    _add_detail(img.reshape(-1, 3), y.reshape(-1), low.reshape(-1), np.float32(amount), out.reshape(-1, 3))
    return out


@njit(cache=True, parallel=True)
def _add_detail(img, y, low, amount, out):
    """out[i, c] = img[i, c] + amount * (y[i] - low[i]), rounded and clipped to 0..255."""
    n = img.shape[0]
    step = 1 << 14
    for chunk in prange((n + step - 1) // step):
        for i in range(chunk * step, min(n, (chunk + 1) * step)):
            d = amount * (y[i] - low[i]) + np.float32(0.5)
            for c in range(3):
                v = min(max(np.float32(img[i, c]) + d, np.float32(0.0)), np.float32(255.0))
                out[i, c] = np.uint8(v)


@njit(cache=True, parallel=True)
def _apply_lut(rgb, lut, out):
    """out[i, c] = lut[c, rgb[i, c]] over the flattened pixels."""
    n = rgb.shape[0]
    step = 1 << 14
    for chunk in prange((n + step - 1) // step):
        for i in range(chunk * step, min(n, (chunk + 1) * step)):
            out[i, 0] = lut[0, rgb[i, 0]]
            out[i, 1] = lut[1, rgb[i, 1]]
            out[i, 2] = lut[2, rgb[i, 2]]


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
