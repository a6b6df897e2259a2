"""EMVA 1288 sensor model: scene radiance -> photons -> electrons -> digital numbers, per pixel.

For each pixel (through its colour filter: Bayer channel, or luma for a mono sensor) over an exposure of
``t`` seconds:

    photons   mu_p = radiance * flux_photons_per_s * t
    electrons mu_e = QE * mu_p * (1 + PRNU_pattern) + dark_current * t
    signal    e    = Poisson(mu_e) + DSNU_pattern, clipped at full_well
    DN             = round((e + read_noise * N(0, 1)) * K * analog_gain * digital_gain + black_level)

clipped to the ADC's range ``0 .. 2**bit_depth - 1``. Only those two clip, as in a real pixel: the DSNU offset
is relative to the mean dark signal, so a dark pixel's signal may fall below it (below the black level in DN),
and the black level keeps those negative excursions in the output. K is the system gain (DN per electron at
unity gain). Every stage can be switched off (``STAGES``). Noise is reproducible: temporal noise depends only
on (seed, frame index, pixel), fixed patterns only on (serial number, pixel position on the array), through a
counter-based hash (SplitMix64), so frame n's noise does not depend on which frames were drawn before it and a
cropped mode sees the same pattern as the full array. Gaussian draws are Box-Muller pairs on the hash's
bits (``rollcam.sim._rng``: exact to float32 precision, |z| up to 6.7, vectorised). Shot noise is exact
Poisson (inversion) below 30 electrons and Gaussian with variance mu_e above, where the two agree to within
the skew of 1/sqrt(30); where the signal is further than 6 sigma from the full well, shot and read noise are
drawn as one Gaussian of summed variance (the same distribution, one draw instead of two).

``flux_photons_per_s`` is the photon flux per pixel at linear radiance 1.0 (lens and pixel area folded in;
``SensorModel``'s own, else the sensor YAML's ``noise.flux_photons_per_s``); by default, linear 1.0 fills
the full well at the 10 ms reference exposure and unity gain, so a sensor-path frame at default settings is
as bright as the clean render.

``SensorModel.expose`` takes the radiance as an array or as a ``LinearFrame`` (the renderer's static
composite plus painted lines), read in place; the output is the same, bit for bit, either way. A static
composite's per-pixel mean and noise spread (in DN, at the frame's exposure and gain) are computed once and
kept, so a frame reads two float32 per static pixel, computes its painted lines, and draws one normal per
pixel; only rows with dark pixels or pixels near the full well take the exact per-pixel pass (the kernels
and their loops: ``rollcam.sim._sensor_kernels``).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.common.values import SERIAL

from . import _sensor_kernels as kern
from ._jitcache import guard
from ._sensor_kernels import POISSON_EXACT_BELOW_E
from .hwconfig import NoiseParams
from .render.result import LinearFrame

STAGES = ("shot", "dark", "read", "dsnu", "prnu", "saturation", "quantization")
"""Switchable stages of the model (all on by default; ``NoiseParams.ideal`` turns the random ones off)."""
RANDOM_STAGES = frozenset({"shot", "dark", "read", "dsnu", "prnu"})
REFERENCE_EXPOSURE_S = 0.010
__all__ = ["POISSON_EXACT_BELOW_E", "RANDOM_STAGES", "REFERENCE_EXPOSURE_S", "STAGES", "SensorModel", "parse_stages",
           "split_gain"]

def _key(*parts: object) -> np.uint64:
    digest = hashlib.blake2b(repr(parts).encode(), digest_size=8).digest()
    return np.uint64(int.from_bytes(digest, "little"))


@dataclass(frozen=True)
class SensorModel:
    """One emulated sensor's pixel physics: its EMVA figures, ADC depth, colour filter and serial number.

    ``stages`` names the stages that run (see ``STAGES``); ``ideal`` params drop the random ones.
    """

    noise: NoiseParams
    bit_depth: int
    cfa: str
    serial: str = SERIAL
    seed: int = 0
    stages: frozenset[str] = field(default_factory=lambda: frozenset(STAGES))
    flux_photons_per_s: float | None = None
    _patterns: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    _statics: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        unknown = set(self.stages) - set(STAGES)
        if unknown:
            raise ConfigError(f"unknown noise stage(s) {sorted(unknown)}; stages are {list(STAGES)}")
        if not 1 <= self.bit_depth <= 16:
            raise ConfigError(f"bit depth must be in 1..16, got {self.bit_depth!r}")
        if self.cfa not in ("RGGB", "BGGR", "GRBG", "GBRG", "mono"):
            raise ConfigError(f"CFA {self.cfa!r} is not a Bayer order or 'mono'")
        stages = frozenset(self.stages) - (RANDOM_STAGES if self.noise.ideal else frozenset())
        object.__setattr__(self, "stages", stages)

    @property
    def flux(self) -> float:
        """Photons per pixel per second at linear radiance 1.0."""
        if self.flux_photons_per_s is not None:
            return self.flux_photons_per_s
        if self.noise.flux_photons_per_s is not None:
            return self.noise.flux_photons_per_s
        return self.noise.full_well_e / (self.noise.quantum_efficiency * REFERENCE_EXPOSURE_S)

    @property
    def max_dn(self) -> int:
        """Largest ADC output."""
        return (1 << self.bit_depth) - 1

    def system_gain(self, analog_gain: float = 1.0, digital_gain: float = 1.0) -> float:
        """DN per electron at these gains (EMVA K)."""
        return self.noise.system_gain_dn_per_e * analog_gain * digital_gain

    def fixed_patterns(self, h: int, w: int, origin: tuple[int, int] = (0, 0), array_width: int | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
        """PRNU gain and DSNU offset (electrons) maps, float32 (h, w), of the pixels at ``origin`` on the array.

        They depend on the serial number and pixel position only; computed once per geometry and kept.
        """
        key = (h, w, int(origin[0]), int(origin[1]), int(array_width or w))
        cache = self._patterns
        if key not in cache:
            if len(cache) >= 4:  # a stream uses one geometry; keep a few, not every size ever asked for
                cache.pop(next(iter(cache)))
            gain_map, off_map = np.empty((h, w), np.float32), np.empty((h, w), np.float32)
            kern.fixed_patterns(_key("fixed", str(self.serial)), key[2], key[3], key[4], self.noise.prnu_fraction,
                                self.noise.dsnu_e, gain_map, off_map)
            cache[key] = (gain_map, off_map)
        return cache[key]

    def _static(self, static: np.ndarray, by_col: bool, cfa: np.ndarray, on: np.ndarray, maps: tuple,
                p: np.ndarray) -> tuple[np.ndarray, ...]:
        """What frames keep of a shared, read-only static composite: for a row readout its ``plan`` (mean and
        spread in DN per pixel, uncommon pixels per row) at this exposure and gain, for a column readout its
        mosaic (filtered radiance; colour float32, exact; mono luma float64). Computed once and kept.

        Keyed by the array that owns the composite's memory (held, so the key cannot be reused); a renderer
        never writes its composite after building it.
        """
        owner = static if static.base is None else static.base
        key = (id(owner), static.shape, static.strides, by_col, id(maps[0]), *([] if by_col else [*p, *on]))
        hit = self._statics.get(key)
        if hit is not None and hit[0] is owner:
            return hit[1]
        h, w = static.shape[1::-1] if by_col else static.shape[:2]
        mono = self.cfa == "mono"
        empty = np.empty((0, 0), np.float32)
        if by_col:
            mos = np.empty((h, w), np.float64 if mono else np.float32)
            kern.mosaic(static, by_col, cfa, mono, mos)
            kept: tuple[np.ndarray, ...] = (mos, empty, empty, np.empty(0, np.int64))
        else:
            plan_m, plan_s, plan_n = np.empty((h, w), np.float32), np.empty((h, w), np.float32), np.empty(h, np.int64)
            kern.plan(static, cfa, mono, on, maps[0], maps[1], p, plan_m, plan_s, plan_n)
            kept = (empty, plan_m, plan_s, plan_n)
        if len(self._statics) >= 2:  # a stream has one composite; keep a spare, not every one ever seen
            self._statics.pop(next(iter(self._statics)))
        self._statics[key] = (owner, kept)
        return kept

    def expose(self, radiance: np.ndarray | LinearFrame, exposure_ns: int, frame_index: int, *,
               analog_gain: float = 1.0, digital_gain: float = 1.0, origin: tuple[int, int] = (0, 0),
               array_width: int | None = None) -> np.ndarray:
        """Linear RGB radiance ``(H, W, 3)`` over ``exposure_ns`` -> ADC samples ``uint16 (H, W)``.

        ``radiance`` may be a ``LinearFrame`` (static composite plus painted lines), read in place.

        With the 'quantization' stage off, returns float64 DN before rounding and clipping (for analysis).
        ``origin`` (top, left) and ``array_width`` place the image on the pixel array, for the fixed patterns.
        """
        if isinstance(radiance, LinearFrame):
            over, by_col, use_over = radiance.lines, radiance.by_column, radiance.painted
            base = radiance.static if radiance.static is not None else over
            if base.shape != over.shape or use_over.shape != over.shape[:1] or over.dtype != np.float32:
                raise ConfigError(f"inconsistent LinearFrame: static {base.shape}, lines {over.shape} {over.dtype}, "
                                  f"painted {use_over.shape}")
            h, w = over.shape[1::-1] if by_col else over.shape[:2]
        else:
            if radiance.ndim != 3 or radiance.shape[2] != 3:
                raise ConfigError(f"radiance must be (H, W, 3), got shape {radiance.shape}")
            base = over = np.ascontiguousarray(radiance, dtype=np.float32)
            by_col, use_over = False, np.zeros(radiance.shape[0], np.bool_)
            h, w = radiance.shape[:2]
        if not isinstance(exposure_ns, (int, np.integer)) or exposure_ns < 0:
            raise ConfigError(f"exposure must be a whole number of ns >= 0, got {exposure_ns!r}")
        for name, g in (("analog_gain", analog_gain), ("digital_gain", digital_gain)):
            if not math.isfinite(g) or g <= 0:
                raise ConfigError(f"{name} must be a finite number > 0, got {g!r}")
        t_s = int(exposure_ns) * 1e-9
        n = self.noise
        s = self.stages
        from .formats import cfa_channels

        cfa = cfa_channels(self.cfa, rgb=True) if self.cfa != "mono" else np.zeros((2, 2), np.int64)
        on = np.array([st in s for st in ("shot", "dark", "read", "dsnu", "prnu", "saturation")], np.bool_)
        quantize = "quantization" in s
        out_i = np.empty((h, w) if quantize else (0, 0), np.uint16)
        out_f = np.empty((0, 0) if quantize else (h, w), np.float64)
        gain_map, off_map = self.fixed_patterns(h, w, origin, int(array_width or w))
        p = np.zeros(9)
        p[[kern.P_QE, kern.P_FLUX, kern.P_DARK, kern.P_VAR_READ, kern.P_K, kern.P_BLACK, kern.P_FULL_WELL,
           kern.P_READ, kern.P_MAX_DN]] = (
            n.quantum_efficiency, self.flux * t_s, n.dark_current_e_per_s * t_s if on[1] else 0.0,
            n.dark_noise_e ** 2 if on[2] else 0.0, self.system_gain(analog_gain, digital_gain), n.black_level_dn,
            n.full_well_e, n.dark_noise_e, float(self.max_dn))
        empty = np.empty((0, 0), np.float32)
        mos, plan_m, plan_s, plan_n = empty, empty, empty, np.empty(0, np.int64)
        if isinstance(radiance, LinearFrame) and radiance.static is not None and not radiance.static.flags.writeable:
            mos, plan_m, plan_s, plan_n = self._static(radiance.static, bool(by_col), cfa, on, (gain_map, off_map), p)
        kern.expose(base, mos, over, use_over, bool(by_col), cfa, self.cfa == "mono", p,
                    _key("frame", self.seed, int(frame_index)), _key("exact", self.seed, int(frame_index)),
                    int(origin[0]), int(origin[1]), int(array_width or w), on, gain_map, off_map,
                    plan_m, plan_s, plan_n, out_i, out_f, quantize)
        return out_i if quantize else out_f


def parse_stages(text: str | None) -> frozenset[str]:
    """``emu:`` ``noise=`` value -> stages: 'on'/'all'/None all, 'off'/'none' none, or a comma list."""
    if text is None or text in ("on", "all"):
        return frozenset(STAGES)
    if text in ("off", "none"):
        return frozenset({"saturation", "quantization"})
    names = frozenset(t.strip() for t in text.split(",") if t.strip())
    unknown = names - set(STAGES)
    if unknown:
        raise ConfigError(f"noise={text!r}: unknown stage(s) {sorted(unknown)}; use on, off or a comma list "
                          f"of {list(STAGES)}")
    return names | {"quantization"}


def split_gain(total: float, analog: tuple[float, float], digital: tuple[float, float]
               ) -> tuple[float, float, bool]:
    """Total gain -> (analog, digital, clamped): analog first up to its maximum, then digital, as drivers do."""
    if not math.isfinite(total) or total <= 0:
        raise ConfigError(f"gain must be a finite number > 0, got {total!r}")
    a = min(max(total, analog[0]), analog[1])
    d = min(max(total / a, digital[0]), digital[1])
    return a, d, not math.isclose(a * d, total, rel_tol=1e-9)


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
