"""The lens in front of the sensor: relative illumination (vignetting) and the optical point-spread function.

A real lens neither lights the field evenly nor images a point to a point. ``LensOptics`` applies both to
linear scene radiance, before the sensor: on the sensor path between exposure integration and the EMVA model
(so shot noise follows the dimmed corners), on the clean path before the 8-bit encoding. Off (the default) it
does no work at all.

- **Vignetting** follows the cos^4 law of image irradiance (E = E0 cos^4 theta, theta the field angle), with
  the field angle scaled so that the corner pixel receives ``1 - vignette`` of the centre's light: gain(d) =
  (1 + k d^2)^-2 at distance d px from the optical centre (the image centre), k from the corner value. A
  real lens adds mechanical vignetting that falls faster at the very edge; a corner value is what lens data
  sheets quote (relative illumination).
- **Blur** is a Gaussian PSF of standard deviation ``lens_blur_px`` (aberrations and diffraction lumped
  together), integrated over each pixel's aperture (so the sampled kernel keeps the configured variance: a
  point's image has variance sigma^2 + 1/12, Sheppard's correction for the pixel), and a defocus disc
  (pillbox) of radius ``defocus_px``, the circle of confusion of a geometric-optics defocus, also integrated
  over the pixel. Both are separable or isotropic, so they act the same on a frame rendered by columns.

The PSF is applied to the composed frame, whose lines were read at different instants: under a rolling
shutter a pixel mixes lines up to ``psf_radius_px`` away, read ``psf_radius_px x line_time`` apart, which a
real lens (blurring each instant's light before the row reads it) does not. docs/optics.md gives the bound.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from rollcam.common.errors import ConfigError

from .render.result import LinearFrame

MAX_VIGNETTE = 0.95
"""Largest light loss at the corner (5 % relative illumination; wide-angle phone lenses reach ~0.7)."""
MAX_BLUR_SIGMA_PX = 32.0
"""Largest Gaussian PSF sigma, px (a kernel of 257 taps a side)."""
MAX_DEFOCUS_PX = 32.0
"""Largest defocus-disc radius, px (a 2-D kernel of 67 x 67 taps: ~0.2 s a 1080p frame)."""

_BORDER = 2  # cv2.BORDER_REFLECT: light just outside the field mirrors the edge (a flat field stays flat)


@dataclass(frozen=True)
class LensOptics:
    """Vignetting and PSF of the lens (see the module docstring); all zero: no lens effect, no work."""

    vignette: float = 0.0
    lens_blur_px: float = 0.0
    defocus_px: float = 0.0

    def __post_init__(self) -> None:
        for name, hi in (("vignette", MAX_VIGNETTE), ("lens_blur_px", MAX_BLUR_SIGMA_PX),
                         ("defocus_px", MAX_DEFOCUS_PX)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= hi:
                raise ConfigError(f"{name} must be a number in 0..{hi:g}, got {value!r}")

    @property
    def on(self) -> bool:
        """True when the lens changes the image."""
        return bool(self.vignette or self.lens_blur_px or self.defocus_px)

    @property
    def psf_radius_px(self) -> float:
        """How far the PSF reaches, px: 3 sigma of the Gaussian plus the disc's radius (the RS mixing bound)."""
        return 3.0 * self.lens_blur_px + self.defocus_px

    def info(self) -> dict[str, float]:
        """What a frame's metadata records about the lens (the effects that are on)."""
        return {k: v for k, v in (("vignette", self.vignette), ("lens_blur_px", self.lens_blur_px),
                                  ("defocus_px", self.defocus_px)) if v}

    @property
    def reach_lines(self) -> int:
        """Kernel half-size in lines: how far an output pixel's inputs lie (0 without blur)."""
        r = max(int(math.ceil(4.0 * self.lens_blur_px)), 1) if self.lens_blur_px else 0
        return r + (int(math.ceil(self.defocus_px + 0.5)) if self.defocus_px else 0)

    def apply(self, radiance: np.ndarray | LinearFrame, out: np.ndarray | None = None,
              scratch: np.ndarray | None = None) -> np.ndarray:
        """Linear radiance ``(lines, along, 3)`` (an array, or a ``LinearFrame`` in its render orientation)
        through the lens: a C-contiguous float32 array in the same orientation. ``out`` and ``scratch`` are
        reusable buffers of that shape (fresh ones when None or of another shape); the result is one of them.
        The input is never written."""
        shape = _shape(radiance)
        bufs = [b if b is not None and b.shape == shape and b.dtype == np.float32 and b.flags.c_contiguous
                else np.empty(shape, np.float32) for b in (out, scratch)]
        return self.filter(_whole(radiance, bufs[1]), bufs, 0, shape[0])

    def filter(self, src: np.ndarray, bufs: list[np.ndarray], first: int, n_lines: int) -> np.ndarray:
        """Lines ``first ..`` of a frame of ``n_lines`` (``src``, C-contiguous float32; the vignette is placed by
        ``first``) through the lens, ping-ponging between ``bufs`` (two buffers of ``src``'s shape, neither of
        them ``src`` unless it is ``bufs[1]``); returns the one holding the result. Lines within
        ``reach_lines`` of a cut edge of ``src`` are only valid at a true frame edge."""
        import cv2

        steps = []
        if self.lens_blur_px:
            k = gaussian_kernel(self.lens_blur_px)
            steps.append(lambda a, dst: cv2.sepFilter2D(a, cv2.CV_32F, k, k, dst=dst, borderType=_BORDER))
        if self.defocus_px:
            disc = disc_kernel(self.defocus_px)
            steps.append(lambda a, dst: cv2.filter2D(a, cv2.CV_32F, disc, dst=dst, borderType=_BORDER))
        if self.vignette:
            gain = _vignette_rgb(self.vignette, n_lines, src.shape[1])[first:first + src.shape[0]]
            steps.append(lambda a, dst: np.multiply(a, gain, out=dst))
        if not steps:
            np.copyto(bufs[0], src)
            return bufs[0]
        for step in steps:  # never writing the input
            dst = bufs[0] if src is not bufs[0] else bufs[1]
            step(src, dst)
            src = dst
        return src


class LensStage:
    """A ``LensOptics`` applied frame after frame to one camera's radiance, doing only the work a frame needs.

    The lens image of the renderer's static composite is computed once and shared (read-only, as the composite
    is); a frame then re-filters only its painted lines and those within ``reach_lines`` of them, from slabs
    padded by ``reach_lines`` on each side, so the lines it returns equal ``LensOptics.apply`` of the whole
    frame. A moving camera (no composite) filters every line.
    """

    def __init__(self, optics: LensOptics) -> None:
        self.optics = optics
        self._static: tuple[np.ndarray, np.ndarray] | None = None  # (composite, its lens image)
        self._bufs: list[np.ndarray] = []

    def radiance(self, frame: LinearFrame) -> LinearFrame:
        """``frame`` through the lens, as a ``LinearFrame`` of the same orientation (lines in this stage's
        reusable buffer, valid until the next call)."""
        n_lines = frame.lines.shape[0]
        out = self._buffer(0, frame.lines.shape)
        if frame.static is None:
            whole = self.optics.apply(frame, out, self._buffer(1, frame.lines.shape))
            return LinearFrame(None, whole, np.ones(n_lines, np.bool_), frame.by_column)
        static = self.static_image(frame.static)
        reach = self.optics.reach_lines
        todo = _dilate(frame.painted, reach)
        for a, b in runs(todo):
            lo, hi = max(a - reach, 0), min(b + reach, n_lines)
            src = self._buffer(1, (hi - lo, *frame.lines.shape[1:]))
            np.copyto(src, frame.static[lo:hi])
            idx = np.flatnonzero(frame.painted[lo:hi])
            src[idx] = frame.lines[lo + idx]
            slab = self.optics.filter(src, [self._buffer(2, src.shape), src], lo, n_lines)
            out[a:b] = slab[a - lo:b - lo]
        return LinearFrame(static, out, todo, frame.by_column)

    def static_image(self, static: np.ndarray) -> np.ndarray:
        """The lens image of a renderer's static composite (read-only), computed on first use."""
        hit = self._static
        owner = static if static.base is None else static.base
        if hit is None or hit[0] is not owner:
            image = self.optics.apply(static)
            image.flags.writeable = False
            hit = self._static = (owner, image)
        return hit[1]

    def _buffer(self, k: int, shape: tuple[int, ...]) -> np.ndarray:
        """Scratch buffer ``k`` viewed as ``shape`` (grown when too small; its pages stay mapped frame to frame)."""
        while len(self._bufs) <= k:
            self._bufs.append(np.empty(0, np.float32))
        size = int(np.prod(shape))
        if self._bufs[k].size < size:
            self._bufs[k] = np.empty(size, np.float32)
        return self._bufs[k][:size].reshape(shape)


def _shape(radiance: np.ndarray | LinearFrame) -> tuple[int, int, int]:
    a = radiance.lines if isinstance(radiance, LinearFrame) else np.asarray(radiance)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ConfigError(f"radiance must be (lines, along, 3), got shape {a.shape}")
    return a.shape  # type: ignore[return-value]


def _whole(radiance: np.ndarray | LinearFrame, scratch: np.ndarray) -> np.ndarray:
    """The frame as one C-contiguous float32 array in its own orientation (a LinearFrame over a composite is
    assembled in ``scratch``)."""
    if isinstance(radiance, LinearFrame):
        if radiance.static is None:
            return np.ascontiguousarray(radiance.lines, np.float32)
        np.copyto(scratch, radiance.static)
        idx = np.flatnonzero(radiance.painted)
        scratch[idx] = radiance.lines[idx]
        return scratch
    return np.ascontiguousarray(radiance, np.float32)


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """The ``[start, end)`` runs of True in a 1-D bool mask."""
    edges = np.flatnonzero(np.diff(np.concatenate(([False], mask, [False])).astype(np.int8)))
    return list(zip(edges[0::2].tolist(), edges[1::2].tolist(), strict=True))


def _dilate(mask: np.ndarray, reach: int) -> np.ndarray:
    """``mask`` with every True spread ``reach`` entries either way."""
    if reach == 0 or not mask.any():
        return mask.copy()
    c = np.concatenate(([0], np.cumsum(mask, dtype=np.int64)))
    n = mask.shape[0]
    i = np.arange(n)
    return c[np.minimum(i + reach + 1, n)] - c[np.maximum(i - reach, 0)] > 0


@functools.lru_cache(maxsize=8)
def vignette_map(vignette: float, n_lines: int, n_along: int) -> np.ndarray:
    """float32 ``(n_lines, n_along)`` relative illumination: 1 at the centre, ``1 - vignette`` at the corner
    pixels' centres, cos^4 in between. Symmetric, so a frame rendered by columns gets the same map."""
    cy, cx = (n_lines - 1) / 2.0, (n_along - 1) / 2.0
    d2_corner = cx * cx + cy * cy
    k = ((1.0 - vignette) ** -0.5 - 1.0) / max(d2_corner, 1e-12)  # (1 + k d_c^2)^-2 = 1 - vignette
    y = (np.arange(n_lines, dtype=np.float64) - cy) ** 2
    x = (np.arange(n_along, dtype=np.float64) - cx) ** 2
    gain = (1.0 + k * (y[:, None] + x[None, :])) ** -2
    out = gain.astype(np.float32)
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=2)
def _vignette_rgb(vignette: float, n_lines: int, n_along: int) -> np.ndarray:
    """``vignette_map`` repeated over the three channels (a same-shape multiply is twice a broadcast's speed)."""
    out = np.ascontiguousarray(np.repeat(vignette_map(vignette, n_lines, n_along)[..., None], 3, axis=2))
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=8)
def gaussian_kernel(sigma_px: float) -> np.ndarray:
    """1-D float32 taps of a Gaussian of ``sigma_px`` integrated over each pixel (to 4 sigma, summing to 1)."""
    r = max(int(math.ceil(4.0 * sigma_px)), 1)
    edges = (np.arange(-r, r + 2, dtype=np.float64) - 0.5) / (sigma_px * math.sqrt(2.0))
    cdf = 0.5 * (1.0 + np.array([math.erf(e) for e in edges]))
    taps = np.diff(cdf)
    return (taps / taps.sum()).astype(np.float32)


@functools.lru_cache(maxsize=8)
def disc_kernel(radius_px: float, supersample: int = 16) -> np.ndarray:
    """2-D float32 taps of a uniform disc of ``radius_px`` integrated over each pixel (``supersample`` x
    ``supersample`` points a pixel), summing to 1."""
    r = int(math.ceil(radius_px + 0.5))
    s = (np.arange(supersample) + 0.5) / supersample - 0.5
    grid = (np.arange(-r, r + 1)[:, None] + s[None, :]).reshape(-1)
    inside = (grid[:, None] ** 2 + grid[None, :] ** 2) <= radius_px * radius_px
    n = 2 * r + 1
    taps = inside.reshape(n, supersample, n, supersample).sum(axis=(1, 3)).astype(np.float64)
    if taps.sum() == 0:  # a disc smaller than one sub-sample: a point
        taps[r, r] = 1.0
    return (taps / taps.sum()).astype(np.float32)
