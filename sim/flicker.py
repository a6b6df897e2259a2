"""Light that changes in time: mains-lamp and PWM-LED waveforms and their exact means over exposure windows.

A modulated light's output is ``(1 - depth) + depth * shape(f t + phase)``, where ``shape`` has period 1, mean 1
and minimum 0, so the light's time average is its nominal level whatever the waveform. Three shapes cover the
lamps on a street:

- ``sine``: ``1 + cos(2 pi u)``, a filament lamp (incandescent, halogen): its thermal mass smooths the mains
  power ``sin^2`` into a shallow ripple at twice the mains frequency.
- ``rectified``: ``(pi / 2) |sin(pi u)|``, a discharge lamp on a magnetic ballast (fluorescent, sodium): light
  follows the current, going (nearly) dark at every zero crossing, twice per mains cycle.
- ``pwm``: ``1 / duty`` for the first ``duty`` of each period, else 0: an LED dimmed by pulse-width modulation
  (signs, traffic lights, many LED street lamps).

A pixel integrates the light over its exposure window, so what a line sees is the waveform's *mean* over that
line's window ``[t0, t1]`` on the device clock, computed exactly from the shape's antiderivative
(``Waveform.window_mean``), never by sampling. On a rolling shutter consecutive lines' windows slide by one line
time, so the frame shows bands of period ``1 / (f * line_time)`` lines whose contrast falls as the exposure
covers more of a period (for ``sine``, by ``|sinc(f * exposure)|``; none at all at exposure = k / f); on a
global shutter every line shares one window and the whole frame changes brightness from frame to frame instead.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from rollcam.common.errors import ConfigError

SHAPES = ("sine", "rectified", "pwm")

LAMPS: dict[str, tuple[str, float]] = {
    # name: (shape, depth). Depths give the flicker percent ((max - min) / (max + min)) such lamps measure:
    # filaments ~4-10 %, magnetic-ballast fluorescent ~30 %, high-pressure sodium ~90-95 % (IEEE 1789 survey).
    "incandescent": ("sine", 0.08),
    "halogen": ("sine", 0.04),
    "fluorescent": ("rectified", 0.35),
    "sodium": ("rectified", 0.95),
}
"""Mains lamps: the waveform shape and modulation depth of each type (light at twice the mains frequency)."""

MAINS_HZ = (50.0, 60.0)
MAX_FREQ_HZ = 1e6
"""Fastest modulation a light may have (PWM drivers run up to a few hundred kHz)."""


@dataclass(frozen=True)
class Waveform:
    """A periodic light waveform normalised to mean 1: ``(1 - depth) + depth * shape(freq_hz * t + phase)``.

    ``phase`` is in cycles (0..1) at device time 0; ``duty`` is the PWM on-fraction (``pwm`` only).
    """

    shape: str
    freq_hz: float
    depth: float = 1.0
    phase: float = 0.0
    duty: float = 0.5

    def __post_init__(self) -> None:
        if self.shape not in SHAPES:
            raise ConfigError(f"waveform shape {self.shape!r} is not one of {SHAPES}")
        if not (math.isfinite(self.freq_hz) and 0 < self.freq_hz <= MAX_FREQ_HZ):
            raise ConfigError(f"light frequency must be in (0, {MAX_FREQ_HZ:g}] Hz, got {self.freq_hz!r}")
        if not (math.isfinite(self.depth) and 0.0 <= self.depth <= 1.0):
            raise ConfigError(f"modulation depth must be in 0..1, got {self.depth!r}")
        if not math.isfinite(self.phase):
            raise ConfigError(f"waveform phase must be finite (cycles), got {self.phase!r}")
        if self.shape == "pwm" and not (math.isfinite(self.duty) and 0.0 < self.duty <= 1.0):
            raise ConfigError(f"PWM duty must be in (0, 1], got {self.duty!r}")

    @classmethod
    def mains(cls, lamp: str, mains_hz: float = 50.0, depth: float | None = None, phase: float = 0.0) -> Waveform:
        """The light of a mains lamp of type ``lamp`` (see ``LAMPS``): twice the mains frequency."""
        if lamp not in LAMPS:
            raise ConfigError(f"lamp {lamp!r} is not one of {list(LAMPS)}")
        if mains_hz not in MAINS_HZ:
            raise ConfigError(f"mains frequency must be one of {MAINS_HZ} Hz, got {mains_hz!r}")
        shape, d = LAMPS[lamp]
        return cls(shape, 2.0 * float(mains_hz), d if depth is None else float(depth), float(phase))

    @classmethod
    def pwm(cls, freq_hz: float, duty: float, phase: float = 0.0, depth: float = 1.0) -> Waveform:
        """A PWM-dimmed LED: on for ``duty`` of each period of ``freq_hz``."""
        return cls("pwm", float(freq_hz), float(depth), float(phase), float(duty))

    @property
    def flicker_percent(self) -> float:
        """(max - min) / (max + min) of the instantaneous light, as flicker meters report it (0..1)."""
        top = {"sine": 2.0, "rectified": math.pi / 2.0, "pwm": 1.0 / self.duty}[self.shape]
        hi, lo = 1.0 - self.depth + self.depth * top, 1.0 - self.depth
        return (hi - lo) / (hi + lo)

    def _cycles(self, t_ns: np.ndarray) -> np.ndarray:
        """Fractional cycle ``frac(freq * t + phase)`` at integer-ns times, exact after any uptime: whole
        seconds and the nanosecond rest are scaled separately, so no product of a large time loses the phase."""
        t = np.asarray(t_ns, np.int64)
        sec, rest = np.divmod(t, 1_000_000_000)
        x = np.mod(self.freq_hz * sec.astype(np.float64), 1.0) + self.freq_hz * rest.astype(np.float64) * 1e-9
        return np.mod(x + self.phase, 1.0)

    def _integral(self, u: np.ndarray) -> np.ndarray:
        """Antiderivative of ``shape`` from 0 (cycles), for any u >= 0: floor(u) + s(frac(u))."""
        whole = np.floor(u)
        f = u - whole
        if self.shape == "sine":
            part = f + np.sin(2.0 * math.pi * f) / (2.0 * math.pi)
        elif self.shape == "rectified":
            part = 0.5 * (1.0 - np.cos(math.pi * f))
        else:
            part = np.minimum(f, self.duty) / self.duty
        return whole + part

    def shape_at(self, u: np.ndarray) -> np.ndarray:
        """``shape`` at cycle positions ``u`` (its instantaneous value, mean 1)."""
        f = np.mod(u, 1.0)
        if self.shape == "sine":
            return 1.0 + np.cos(2.0 * math.pi * f)
        if self.shape == "rectified":
            return 0.5 * math.pi * np.abs(np.sin(math.pi * f))
        return np.where(f < self.duty, 1.0 / self.duty, 0.0)

    def value(self, t_ns: np.ndarray) -> np.ndarray:
        """Instantaneous light (mean 1) at integer-ns times."""
        return 1.0 - self.depth + self.depth * self.shape_at(self._cycles(t_ns))

    def window_mean(self, t0_ns: np.ndarray, t1_ns: np.ndarray) -> np.ndarray:
        """Exact mean of the light over each window ``[t0, t1]`` (integer ns; an empty window gives the
        instantaneous value), float64, mean 1 over whole periods."""
        t0 = np.asarray(t0_ns, np.int64)
        width = np.asarray(t1_ns, np.int64) - t0
        if (width < 0).any():
            raise ConfigError("an exposure window ends before it starts")
        u0 = self._cycles(t0)
        du = self.freq_hz * width.astype(np.float64) * 1e-9  # window length in cycles, from the integer width
        safe = np.where(du > 0, du, 1.0)
        mean = np.where(du > 0, (self._integral(u0 + du) - self._integral(u0)) / safe, self.shape_at(u0))
        return 1.0 - self.depth + self.depth * mean

    def describe(self) -> str:
        """One line for frame metadata and docs."""
        extra = f", duty {self.duty:g}" if self.shape == "pwm" else ""
        return f"{self.shape} {self.freq_hz:g} Hz, depth {self.depth:g}{extra}, phase {self.phase:g}"
