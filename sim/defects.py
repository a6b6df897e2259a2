"""Sensor defects a camera HIL rig injects, made by the sensor model on the ADC samples (before any raw packing
or ISP, so raw and processed formats show the same defects), with the truth of which pixels they hit.

``SensorDefects`` comes from a fault plan (``rollcam.common.faults``: ``stuck=N``, ``dead=N``, ``hot=N``,
``soiling=N``, ``burst=P%``, ``burst_px``, ``hot_dn_per_ms``, ``seed``). Places are fixed on the pixel array by
the plan's seed (a flipped readout shows them mirrored, as a real sensor's do); they are drawn once per array
size and kept. In the order the light and the readout meet them:

- soiling: ``N`` blobs (seeded centre, radius 3..12 % of the shorter side, opacity 0.3..0.8) on the cover glass
  attenuate the signal above black to a transmission ``t = prod(1 - opacity * exp(-(d / r)**2))`` and blur it
  (the signal becomes ``t * (t * s + (1 - t) * blur(s))``, the blur within each CFA colour plane);
- hot pixels: their dark current adds ``hot_dn_per_ms`` DN per ms of exposure at unity gain (times the frame's
  analog and digital gain), clipped at the ADC's full scale;
- stuck pixels: a fixed value each (seeded, between the black level and full scale), whatever the light;
- dead pixels: 0;
- a pixel-error burst, on the frames the plan's ``burst`` rate hits (by frame number): a run of ``burst_px``
  consecutive pixels in readout order from a seeded start reads seeded garbage (0..full scale).

``apply`` returns the samples and the truth, recorded in ``Frame.meta["defects"]`` (and so in ``frames.jsonl``):
``stuck`` ``[[x, y, dn], ...]``, ``dead`` and ``hot`` ``[[x, y], ...]``, ``soiling`` ``[[cx, cy, radius_px,
opacity], ...]`` and the pixels it attenuates by more than 5 % as ``soiled_px``, and on a burst frame ``burst``
``{"x", "y", "length"}`` (its first pixel, in output coordinates, and its length).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from rollcam.common.faults import DEFECTS, FaultPlan

SOILED = 0.95
"""A pixel counts as soiled where the transmission is below this."""


@dataclass(frozen=True)
class _Maps:
    """The defects' places on one array size (array orientation, row-major indices)."""

    stuck: np.ndarray
    stuck_frac: np.ndarray  # where each stuck pixel sits between black and full scale
    dead: np.ndarray
    hot: np.ndarray
    blobs: np.ndarray  # (N, 4): cx, cy, radius_px, opacity
    transmission: np.ndarray | None  # float32 (H, W), None without soiling
    region: tuple[slice, slice] = (slice(0), slice(0))  # where the soiling changes anything (even-aligned)


@dataclass(frozen=True)
class SensorDefects:
    """The defects of one sensor, from the plan that gives them (see the module docstring)."""

    plan: FaultPlan

    @classmethod
    def of(cls, plan: FaultPlan) -> SensorDefects | None:
        """The plan's sensor defects, or None when it gives none (no defect, no burst)."""
        if not any(plan.defect(k) for k in DEFECTS) and not plan.rate("burst"):
            return None
        burst = (("burst", plan.rate("burst")),) if plan.rate("burst") else ()
        return cls(FaultPlan(seed=plan.seed, rates=burst, burst_px=plan.burst_px,
                             hot_dn_per_ms=plan.hot_dn_per_ms, defects=plan.defects))

    def __str__(self) -> str:
        return self.plan.to_text()

    @functools.lru_cache(maxsize=4)  # noqa: B019 - a frozen value object: the cache is its maps per size
    def maps(self, height: int, width: int) -> _Maps:
        """Where the defects sit on an array of this size (drawn from the seed, once)."""
        p = self.plan
        rng = np.random.default_rng([p.seed & 0xFFFFFFFF, p.seed >> 32, 0xDEFEC7])
        counts = [min(p.defect(k), height * width) for k in ("stuck", "dead", "hot")]
        idx = rng.choice(height * width, size=min(sum(counts), height * width), replace=False)
        stuck, dead, hot = np.split(idx, np.cumsum(counts)[:2])
        stuck_frac = rng.random(len(stuck))
        n = p.defect("soiling")
        side = min(height, width)
        blobs = np.stack([rng.uniform(0, width, n), rng.uniform(0, height, n), rng.uniform(0.03, 0.12, n) * side,
                          rng.uniform(0.3, 0.8, n)], axis=1) if n else np.zeros((0, 4))
        t = None
        if n:
            yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
            t = np.ones((height, width), np.float32)
            for cx, cy, r, a in blobs:
                t *= 1 - np.float32(a) * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / np.float32(r * r))
        region = (slice(0), slice(0))
        if t is not None:  # the blobs' reach (transmission visibly below 1), on whole CFA tiles: the only work
            rows, cols = np.nonzero(t < 0.999)
            if len(rows):
                region = (slice(rows.min() & ~1, min(rows.max() + 2, height)),
                          slice(cols.min() & ~1, min(cols.max() + 2, width)))
        return _Maps(stuck, stuck_frac, dead, hot, blobs, t, region)

    def apply(self, dn: np.ndarray, frame_index: int, exposure_ns: int, *, gain: float, black_dn: float,
              max_dn: int, cfa: str, hflip: bool = False, vflip: bool = False) -> tuple[np.ndarray, dict[str, Any]]:
        """ADC samples ``dn`` (uint16 (H, W), output orientation) with the defects made, and their truth."""
        p = self.plan
        h, w = dn.shape
        m = self.maps(h, w)
        out = dn.copy()
        a = out[::-1 if vflip else 1, ::-1 if hflip else 1]  # array orientation: the defects sit on the array
        if m.transmission is not None and a[m.region].size:
            a[m.region] = _soiled(a[m.region], m.transmission[m.region], black_dn, max_dn, cfa)
        flat = a.reshape(-1) if a.flags.c_contiguous else None
        if len(m.hot):
            rows, cols = np.unravel_index(m.hot, (h, w))
            add = p.hot_dn_per_ms * exposure_ns / 1e6 * gain
            a[rows, cols] = np.minimum(a[rows, cols] + add, max_dn).astype(np.uint16)
        stuck_dn = np.round(black_dn + m.stuck_frac * (max_dn - black_dn)).astype(np.uint16)
        for idx, value in ((m.stuck, stuck_dn), (m.dead, np.uint16(0))):
            if len(idx):
                rows, cols = np.unravel_index(idx, (h, w))
                a[rows, cols] = value
        truth: dict[str, Any] = {}

        def xy(idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            rows, cols = np.unravel_index(idx, (h, w))
            return (w - 1 - cols if hflip else cols), (h - 1 - rows if vflip else rows)

        if len(m.stuck):
            x, y = xy(m.stuck)
            truth["stuck"] = [[int(i), int(j), int(v)] for i, j, v in zip(x, y, stuck_dn, strict=True)]
        for name, idx in (("dead", m.dead), ("hot", m.hot)):
            if len(idx):
                x, y = xy(idx)
                truth[name] = [[int(i), int(j)] for i, j in zip(x, y, strict=True)]
        if len(m.blobs):
            truth["soiling"] = [[round(float(cx if not hflip else w - 1 - cx), 2),
                                 round(float(cy if not vflip else h - 1 - cy), 2), round(float(r), 2),
                                 round(float(o), 3)] for cx, cy, r, o in m.blobs]
            truth["soiled_px"] = int((m.transmission < SOILED).sum())
        if p.fires("burst", frame_index):
            n = min(p.burst_px, h * w)
            start = p.pick("burst", frame_index, h * w - n + 1)
            values = np.random.default_rng([p.seed & 0xFFFFFFFF, frame_index & 0xFFFFFFFF, 0xB0757]).integers(
                0, max_dn + 1, n, dtype=np.uint16)
            if flat is not None:
                flat[start:start + n] = values
            else:
                rows, cols = np.unravel_index(np.arange(start, start + n), (h, w))
                a[rows, cols] = values
            x, y = xy(np.array([start]))
            truth["burst"] = {"x": int(x[0]), "y": int(y[0]), "length": n}
        return out, truth


def _soiled(a: np.ndarray, t: np.ndarray, black_dn: float, max_dn: int, cfa: str) -> np.ndarray:
    """Samples ``a`` (array orientation) under a soiled cover glass of transmission ``t``: attenuated above
    black and blurred, within each colour plane of the CFA."""
    s = a.astype(np.float32) - np.float32(black_dn)
    out = np.empty_like(s)
    step = 1 if cfa == "mono" else 2
    for dy in range(step):
        for dx in range(step):
            sub, ts = s[dy::step, dx::step], t[dy::step, dx::step]
            blurred = cv2.blur(np.ascontiguousarray(sub), (5, 5), borderType=cv2.BORDER_REPLICATE)
            out[dy::step, dx::step] = ts * (ts * sub + (1 - ts) * blurred)
    return np.clip(np.rint(out + np.float32(black_dn)), 0, max_dn).astype(np.uint16)

