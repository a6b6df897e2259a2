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
cropped mode sees the same pattern as the full array. Gaussian draws come from a 65,536-entry inverse-CDF
table with linear interpolation (rescaled to unit variance; tails truncated at 4.4 sigma). Shot noise is exact
Poisson (inversion) below 30 electrons and Gaussian with variance mu_e above, where the two agree to within
the skew of 1/sqrt(30); where the signal is further than 6 sigma from the full well, shot and read noise are
drawn as one Gaussian of summed variance (the same distribution, one draw instead of two).

``flux_photons_per_s`` is the photon flux per pixel at linear radiance 1.0 (lens and pixel area folded in;
``SensorModel``'s own, else the sensor YAML's ``noise.flux_photons_per_s``); by default, linear 1.0 fills
the full well at the 10 ms reference exposure and unity gain, so a sensor-path frame at default settings is
as bright as the clean render.

``SensorModel.expose`` takes the radiance as an array or as a ``LinearFrame`` (the renderer's static
composite plus painted lines), read in place; the composite is passed through the colour filter once and
kept, so a frame reads one value per static pixel; the output is the same, bit for bit, either way. Each
row runs in straight (vectorisable) loops: its mean electrons in one, the hash in one, the table lookups
apart in one (gathers would stop the rest vectorising), then shot plus read noise, rounding and the write
in one, which also counts the row's pixels outside the common case (dark or near the full well); only rows
with any take the per-pixel pass for them.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit, prange
from rollcam.common.errors import ConfigError

from ._jitcache import guard
from .hwconfig import NoiseParams
from .render_result import LinearFrame

STAGES = ("shot", "dark", "read", "dsnu", "prnu", "saturation", "quantization")
"""Switchable stages of the model (all on by default; ``NoiseParams.ideal`` turns the random ones off)."""
RANDOM_STAGES = frozenset({"shot", "dark", "read", "dsnu", "prnu"})
REFERENCE_EXPOSURE_S = 0.010
POISSON_EXACT_BELOW_E = 30.0

_M1, _M2, _GOLD = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB), np.uint64(0x9E3779B97F4A7C15)


def _normal_table(n: int = 1 << 16) -> np.ndarray:
    """Inverse normal CDF at n + 1 evenly spaced probabilities (ends pulled in half a cell), unit variance."""
    from statistics import NormalDist

    p = np.clip(np.arange(n + 1) / n, 0.5 / n, 1 - 0.5 / n)
    inv = NormalDist().inv_cdf
    t = np.array([inv(float(q)) for q in p])
    # The piecewise-linear distribution this table gives: variance of each cell's uniform segment, exactly.
    a, b = t[:-1], t[1:]
    var = np.mean((a * a + a * b + b * b) / 3.0)
    return (t / math.sqrt(var)).astype(np.float64)


_TABLE: np.ndarray | None = None


def normal_table() -> np.ndarray:
    """The shared inverse-CDF table (built once, ~0.2 s)."""
    global _TABLE
    if _TABLE is None:
        _TABLE = _normal_table()
    return _TABLE


@njit(cache=True, inline="always")
def _mix(z):
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    return z ^ (z >> np.uint64(31))


@njit(cache=True, inline="always")
def _normal(bits32, table):
    """A standard normal from 32 random bits: 16 bits pick the table cell, 16 interpolate within it."""
    b = np.int64(bits32)  # signed: float conversion of unsigned 64-bit ints is slow on x86
    i = b >> 16
    f = float(b & 0xFFFF) * (1.0 / 65536.0)
    a = table[i]
    return a + f * (table[i + 1] - a)


@njit(cache=True, inline="always")
def _poisson(lam, u):
    p = math.exp(-lam)
    cdf = p
    k = 0
    while u > cdf and k < 1000:
        k += 1
        p *= lam / k
        cdf += p
    return float(k)


@njit(cache=True, parallel=True)
def _fixed_patterns(fp_key, oy, ox, array_w, prnu, dsnu_e, table, gain_map, off_map):
    """PRNU gain (1 + prnu * N) and DSNU offset (dsnu * N, electrons) of each pixel, from its array position."""
    h, w = gain_map.shape
    mask32 = np.uint64(0xFFFFFFFF)
    for y in prange(h):
        row_idx = np.uint64((y + oy) * array_w + ox)
        for x in range(w):
            hf = _mix(fp_key + (row_idx + np.uint64(x)) * _GOLD)
            gain_map[y, x] = max(1.0 + prnu * _normal(hf >> np.uint64(32), table), 0.0)
            off_map[y, x] = dsnu_e * _normal(hf & mask32, table)


@njit(cache=True, inline="always")
def _radiance(lin, ln, al, mono, ch):
    """Radiance a pixel's filter passes: channel ``ch`` of its Bayer colour, or luma for a mono sensor."""
    if mono:
        return 0.2126 * lin[ln, al, 0] + 0.7152 * lin[ln, al, 1] + 0.0722 * lin[ln, al, 2]
    return lin[ln, al, ch]


@njit(cache=True, parallel=True)
def _mosaic(lin, by_col, cfa, mono, out):
    """out[y, x] = the radiance pixel (y, x)'s filter passes, from ``lin`` in render orientation."""
    h, w = out.shape
    for y in prange(h):
        for x in range(w):
            ln, al = np.int64(y), np.int64(x)
            if by_col:
                ln, al = np.int64(x), np.int64(y)
            out[y, x] = _radiance(lin, ln, al, mono, cfa[y & 1, x & 1])


@njit(cache=True)
def _row_radiance(lin, y, mono, cfa, out):
    """out[x] = filtered radiance of row ``y`` from ``lin`` in row orientation (even/odd columns apart)."""
    w = out.shape[0]
    if mono:
        for x in range(w):
            out[x] = 0.2126 * lin[y, x, 0] + 0.7152 * lin[y, x, 1] + 0.0722 * lin[y, x, 2]
        return
    for dx in range(2):
        ch = cfa[y & 1, dx]
        for x in range(dx, w, 2):
            out[x] = lin[y, x, ch]


@njit(cache=True)
def _col_radiance(lin, y, mono, cfa, out, x_from_over, over_flag):
    """Like ``_row_radiance`` for column-major ``lin`` (line = x), only where use_over[x] == over_flag."""
    for x in range(out.shape[0]):
        if x_from_over[x] == over_flag:
            out[x] = _radiance(lin, np.int64(x), np.int64(y), mono, cfa[y & 1, x & 1])


@njit(cache=True, parallel=True, fastmath=True)
def _expose(base, mos, over, use_over, by_col, cfa, mono, flux_s, qe, dark_e, read_e, full_well, k_dn, black, max_dn,
            frame_key, oy, ox, array_w, on, table, gain_map, off_map, out_int, out_f, quantize):
    """The per-pixel model; ``on`` = flags (shot, dark, read, dsnu, prnu, saturation).

    Radiance of line ``ln`` (row, or column when ``by_col``; arrays in render orientation) is read from
    ``over`` where ``use_over[ln]``, else from ``base``: a frame held as a static composite plus painted lines.
    A non-empty ``mos`` is ``base`` already through the colour filter (``_mosaic``), read instead of it: one
    value per pixel rather than three. Straight loops per row; the per-pixel pass (exact Poisson, clipping)
    runs only on rows that have pixels needing it.
    """
    has_mos = mos.shape[0] > 0
    h, w = out_int.shape if quantize else out_f.shape
    shot, dark, read, dsnu_on, prnu_on, sat = on[0], on[1], on[2], on[3], on[4], on[5]
    draw = shot or read  # the per-pixel hash feeds only the temporal draws
    var_read = read_e * read_e if read else 0.0
    mask32 = np.uint64(0xFFFFFFFF)
    n_chunks = min(h, 64)
    ones, zeros = np.ones(w, np.float32), np.zeros(w, np.float32)
    dark_add = dark_e if dark else 0.0
    for chunk in prange(n_chunks):
        mu_row, nrm_row = np.empty(w), np.empty(w)
        ht_row = np.empty(w, np.uint64)
        for y in range(chunk, h, n_chunks):
            # Mean electrons of the row: filtered radiance, PRNU, dark current.
            if by_col:
                _col_radiance(over, y, mono, cfa, mu_row, use_over, True)
                if has_mos:
                    for x in range(w):
                        if not use_over[x]:
                            mu_row[x] = mos[y, x]
                else:
                    _col_radiance(base, y, mono, cfa, mu_row, use_over, False)
            elif use_over[y]:
                _row_radiance(over, y, mono, cfa, mu_row)
            elif has_mos:
                for x in range(w):
                    mu_row[x] = mos[y, x]
            else:
                _row_radiance(base, y, mono, cfa, mu_row)
            gain_row = gain_map[y] if prnu_on else ones
            for x in range(w):  # x * 1.0 and x + 0.0 are exact: the same values as separate optional steps
                mu_row[x] = qe * max(mu_row[x], 0.0) * flux_s * gain_row[x] + dark_add
            row_idx = np.uint64((y + oy) * array_w + ox)
            # The common case first, for every pixel in straight loops: shot and read noise as one Gaussian
            # of summed variance (exact where mu >= POISSON_EXACT_BELOW_E and 6 sigma below the full well),
            # written out at once.
            if draw:
                for x in range(w):
                    ht_row[x] = _mix(frame_key + (row_idx + np.uint64(x)) * _GOLD)
            else:
                ht_row[:] = 0
            off_row = off_map[y] if dsnu_on else zeros
            n_rest = w
            if shot:
                for x in range(w):  # the table gathers apart, so the loop below vectorises
                    nrm_row[x] = _normal(ht_row[x] >> np.uint64(32), table)
                n_rest = 0
                for x in range(w):
                    mu, off = mu_row[x], off_row[x]
                    e = mu + off + math.sqrt(max(mu, 0.0) + var_read) * nrm_row[x]
                    room = full_well - mu - off  # mu + off + 6 sqrt(mu) < full_well, without the square root
                    n_rest += (mu < POISSON_EXACT_BELOW_E) | (sat & ((room <= 0.0) | (36.0 * mu >= room * room)))
                    if quantize:
                        out_int[y, x] = _dn(e, k_dn, black, max_dn)
                    else:
                        out_f[y, x] = e * k_dn + black
            # Then the pixels outside it, one by one (dark ones: exact Poisson; near the full well: clipped),
            # when the row has any: counted in the straight loop, so most rows skip this pass.
            if n_rest == 0:
                continue
            for x in range(w):
                mu, off, ht = mu_row[x], off_row[x], ht_row[x]
                room = full_well - mu - off
                if shot and mu >= POISSON_EXACT_BELOW_E and (not sat or (room > 0.0 and 36.0 * mu < room * room)):
                    continue
                if shot and mu < POISSON_EXACT_BELOW_E:
                    e = _poisson(max(mu, 0.0), float(np.int64(ht >> np.uint64(32))) * (1.0 / 4294967296.0))
                elif shot:
                    e = mu + math.sqrt(mu) * _normal(ht >> np.uint64(32), table)
                else:
                    e = mu
                e += off
                if sat:
                    # The well holds at most the full well. No clip at 0: the DSNU offset is relative to the
                    # mean dark signal, so a dark pixel may read below it; the black level keeps that visible
                    # and the ADC clips at 0 DN (``_dn``).
                    e = min(e, full_well)
                if read:
                    e += read_e * _normal(ht & mask32, table)
                if quantize:
                    out_int[y, x] = _dn(e, k_dn, black, max_dn)
                else:
                    out_f[y, x] = e * k_dn + black


@njit(cache=True, inline="always")
def _dn(e, k_dn, black, max_dn):
    """Electrons -> ADC sample: round half up, then clip (on the clipped, non-negative value truncation floors)."""
    return np.uint16(np.int64(min(max(e * k_dn + black + 0.5, 0.0), max_dn)))


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
    serial: str = "0"
    seed: int = 0
    stages: frozenset[str] = field(default_factory=lambda: frozenset(STAGES))
    flux_photons_per_s: float | None = None
    _patterns: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    _mosaics: dict = field(default_factory=dict, init=False, repr=False, compare=False)

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
            _fixed_patterns(_key("fixed", str(self.serial)), key[2], key[3], key[4], self.noise.prnu_fraction,
                            self.noise.dsnu_e, normal_table(), gain_map, off_map)
            cache[key] = (gain_map, off_map)
        return cache[key]

    def _static_mosaic(self, static: np.ndarray, by_col: bool, cfa: np.ndarray) -> np.ndarray:
        """The filtered radiance of a shared, read-only static composite, computed once and kept.

        Keyed by the array that owns the composite's memory (held, so the key cannot be reused); a renderer
        never writes its composite after building it. Colour keeps float32 (exact); mono luma is float64.
        """
        owner = static if static.base is None else static.base
        key = (id(owner), static.shape, static.strides, by_col, self.cfa)
        hit = self._mosaics.get(key)
        if hit is not None and hit[0] is owner:
            return hit[1]
        h, w = static.shape[1::-1] if by_col else static.shape[:2]
        mos = np.empty((h, w), np.float64 if self.cfa == "mono" else np.float32)
        _mosaic(static, by_col, cfa, self.cfa == "mono", mos)
        if len(self._mosaics) >= 2:  # a stream has one composite; keep a spare, not every one ever seen
            self._mosaics.pop(next(iter(self._mosaics)))
        self._mosaics[key] = (owner, mos)
        return mos

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
        mos = np.empty((0, 0), np.float32)
        if isinstance(radiance, LinearFrame) and radiance.static is not None and not radiance.static.flags.writeable:
            mos = self._static_mosaic(radiance.static, bool(by_col), cfa)
        _expose(base, mos, over, use_over, bool(by_col), cfa, self.cfa == "mono", self.flux * t_s, n.quantum_efficiency,
                n.dark_current_e_per_s * t_s, n.dark_noise_e, n.full_well_e,
                self.system_gain(analog_gain, digital_gain), n.black_level_dn, float(self.max_dn),
                _key("frame", self.seed, int(frame_index)), int(origin[0]), int(origin[1]), int(array_width or w),
                on, normal_table(), gain_map, off_map, out_i, out_f, quantize)
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
