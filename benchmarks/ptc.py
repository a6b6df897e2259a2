"""Photon transfer curve of an emulated sensor, measured from its frames alone: ``rollcam bench --ptc``.

The EMVA 1288 method: pairs of flat-field frames (``emu:SENSOR?scene=flat&level=L&format=RAW``) at
increasing exposure, and dark pairs (``level=0``) at the shortest and longest exposure. For each pair the
mean signal above dark, ``mu = mean(A + B) / 2 - mu_dark``, and the temporal variance,
``var = var(A - B) / 2 - var_dark`` (the difference cancels DSNU and PRNU). Then:

- system gain K (DN/e-): slope of var against mu through the origin, on points below 70% of saturation,
  divided by the gain the frames' metadata records (a sensor whose minimum analog gain exceeds 1 cannot
  run at unity), so it compares with the configured K at unity gain;
- read noise (e-): sqrt(var_dark - 1/12) / (K * g) from a dark pair at the shortest exposure and the
  sensor's highest analog gain g (1/12 DN^2 is the ADC's quantisation, a correction that holds only while
  the read noise spans a DN or more: at unity gain a low-gain sensor's read noise is a fraction of a DN);
- saturation: EMVA's saturation point is the mean at maximum variance; the full well is the plateau, the
  largest mean above dark, over K at the applied gain (``adc_limited`` when the plateau is the ADC's top
  code rather than the full well).

Frames are read through ``open_camera``, as any capture would be; the configured figures come from the
sensor's YAML only to print the comparison.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.sim.codecs import codec
from rollcam.sim.formats import bayer_fourcc, pixel_format
from rollcam.sim.hwconfig import load_sensor
from rollcam.sim.noise import REFERENCE_EXPOSURE_S

LINEAR_FRACTION = 0.7


@dataclass
class PtcResult:
    """Measured and configured figures of one PTC run, and its points (exposure, mean, variance)."""

    sensor: str
    pixel_format: str
    size: tuple[int, int]
    level: float
    applied_gain: float
    gain_dn_per_e: float
    gain_configured: float
    read_noise_e: float
    read_noise_configured: float
    full_well_e: float
    full_well_configured: float
    saturation_capacity_e: float
    adc_limited: bool
    points: list[dict[str, float]]

    def errors(self) -> dict[str, float]:
        """Relative errors (measured / configured - 1) of gain, read noise and full well."""
        def rel(a: float, b: float) -> float:
            return a / b - 1.0 if b else (0.0 if a == 0 else math.inf)

        return {"gain": rel(self.gain_dn_per_e, self.gain_configured),
                "read_noise": rel(self.read_noise_e, self.read_noise_configured),
                "full_well": rel(self.full_well_e, self.full_well_configured)}

    def to_json(self) -> dict[str, Any]:
        """Plain-JSON form (``ptc.json``)."""
        doc = asdict(self)
        doc["errors"] = self.errors()
        return doc


def _raw_format(sensor_name: str) -> str:
    """The sensor's unpacked raw format at its full ADC depth (what a PTC measures on)."""
    s = load_sensor(sensor_name)
    return bayer_fourcc(s.bayer_order, s.bit_depth) if s.bayer_order != "mono" else \
        {8: "GREY", 10: "Y10 ", 12: "Y12 ", 16: "Y16 "}[s.bit_depth]


def _pair(uri: str, width: int) -> tuple[np.ndarray, np.ndarray, int, float]:
    """Two frames of ``uri`` as float samples, their exposure and the total gain their metadata records."""
    from rollcam.host import open_camera

    with open_camera(uri) as cam:
        a, b = cam.read(), cam.read()
    assert a is not None and b is not None
    fa = codec(a.format).decode(a.data, width, a.height).astype(np.float64)
    fb = codec(b.format).decode(b.data, width, b.height).astype(np.float64)
    return fa, fb, int(a.exposure_ns), float(a.meta["analog_gain"] * a.meta["digital_gain"])


def _stats(fa: np.ndarray, fb: np.ndarray) -> tuple[float, float]:
    return float((fa.mean() + fb.mean()) / 2), float(np.var(fa - fb) / 2)


def measure_ptc(sensor: str = "imx219", *, size: tuple[int, int] = (256, 192), steps: int = 24,
                level: float | None = None, serial: str = "ptc", seed: int = 0) -> PtcResult:
    """Run the photon transfer measurement on ``emu:sensor`` (see the module docstring)."""
    if steps < 4:
        raise ConfigError(f"a PTC needs at least 4 exposure steps, got {steps!r}")
    cfg = load_sensor(sensor)
    fourcc = _raw_format(sensor)
    w, h = size
    base = f"emu:{sensor}?scene=flat&format={fourcc.strip()}&size={w}x{h}&serial={serial}&blur_px=0"
    # The exposure range the sensor allows at this size: ask for 0 and for far too long, get both clamps.
    from rollcam.host import open_camera

    with open_camera(base + "&exposure_us=0") as c:
        t_min = c.camera.settings.exposure_ns
    with open_camera(base + "&exposure_us=1e7") as c:
        t_max = c.camera.settings.exposure_ns
    if level is None:  # saturate at about 60% of the longest exposure
        level = REFERENCE_EXPOSURE_S / (0.6 * t_max * 1e-9)
    dark = {}
    for t in (t_min, t_max):
        fa, fb, got, _ = _pair(f"{base}&level=0&exposure_us={t / 1000}&noise_seed={seed}", w)
        dark[got] = _stats(fa, fb)
    (t0, (m0, v0)), (t1, (m1, v1)) = sorted(dark.items())

    def dark_at(t: int) -> tuple[float, float]:
        f = 0.0 if t1 == t0 else (t - t0) / (t1 - t0)
        return m0 + f * (m1 - m0), v0 + f * (v1 - v0)

    points: list[dict[str, float]] = []
    gain = 1.0

    def measure(exposures: np.ndarray) -> None:
        nonlocal gain
        for t_want in exposures:
            i = len(points)
            fa, fb, t, gain = _pair(f"{base}&level={level}&exposure_us={t_want / 1000:.3f}"
                                    f"&noise_seed={seed + 1 + i}", w)
            mean, var = _stats(fa, fb)
            md, vd = dark_at(t)
            points.append({"exposure_ns": t, "mean_dn": mean - md, "var_dn2": var - vd, "mean_raw_dn": mean})

    measure(np.linspace(t_min, t_max, steps))
    # Refine around the variance peak (EMVA's saturation point) with a third as many steps again.
    i_peak = int(np.argmax([p["var_dn2"] for p in points]))
    lo, hi = points[max(i_peak - 1, 0)]["exposure_ns"], points[min(i_peak + 1, len(points) - 1)]["exposure_ns"]
    measure(np.linspace(lo, hi, max(steps // 3, 2) + 2)[1:-1])
    points.sort(key=lambda p: p["exposure_ns"])
    mu = np.array([p["mean_dn"] for p in points])
    var = np.array([p["var_dn2"] for p in points])
    i_sat = int(np.argmax(var))
    lin = (mu > 0) & (mu <= LINEAR_FRACTION * mu[i_sat])
    if lin.sum() < 2:
        raise ConfigError(f"PTC of {sensor!r}: fewer than 2 points below {LINEAR_FRACTION:.0%} of saturation; "
                          "use more steps or a lower level")
    k = float(np.sum(mu[lin] * var[lin]) / np.sum(mu[lin] ** 2))
    fa, fb, _, g_read = _pair(f"{base}&level=0&exposure_us={t_min / 1000}&gain={cfg.gain.analog_max}"
                              f"&noise_seed={seed}", w)
    read_e = math.sqrt(max(_stats(fa, fb)[1] - 1 / 12, 0.0)) / (k * g_read / gain)
    n = cfg.noise
    # The plateau reached the ADC's top code before the full well: the sensor cannot show its full well.
    adc_limited = max(p["mean_raw_dn"] for p in points) > (1 << cfg.bit_depth) - 1.5
    return PtcResult(sensor, fourcc, (w, h), float(level), gain, k / gain, n.system_gain_dn_per_e, read_e,
                     n.dark_noise_e, float(mu.max()) / k, n.full_well_e, float(mu[i_sat]) / k, adc_limited, points)


def plot_ptc(result: PtcResult, path: str | Path) -> None:
    """Variance against mean (log-log), the fitted K line and the saturation point, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mu = np.array([p["mean_dn"] for p in result.points])
    var = np.array([p["var_dn2"] for p in result.points])
    fig, ax = plt.subplots(figsize=(6.5, 5))
    ok = (mu > 0) & (var > 0)
    ax.scatter(mu[ok], var[ok], s=14, label="flat-field pairs")
    xs = np.geomspace(max(mu[ok].min(), 1e-3), mu.max(), 50)
    ax.plot(xs, result.gain_dn_per_e * result.applied_gain * xs, "r-", lw=1,
            label=f"K = {result.gain_dn_per_e:.4f} DN/e- (configured {result.gain_configured:.4f})")
    ax.axvline(result.full_well_e * result.gain_dn_per_e * result.applied_gain, color="grey", ls="--", lw=0.8,
               label=f"full well {result.full_well_e:.0f} e- (configured {result.full_well_configured:.0f})")
    ax.set(xscale="log", yscale="log", xlabel="mean signal above dark (DN)", ylabel="temporal variance (DN^2)",
           title=f"photon transfer: {result.sensor} {result.pixel_format.strip()}, read noise "
                 f"{result.read_noise_e:.2f} e- (configured {result.read_noise_configured:.2f})")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run_ptc(sensor: str, out_dir: str | Path) -> PtcResult:
    """``rollcam bench --ptc``: measure, write ``ptc.json`` and ``ptc.png`` under ``out_dir``."""
    import json

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    result = measure_ptc(sensor)
    (out / "ptc.json").write_text(json.dumps(result.to_json(), indent=1))
    plot_ptc(result, out / "ptc.png")
    return result


def format_ptc(result: PtcResult) -> str:
    """The comparison table ``rollcam bench --ptc`` prints."""
    e = result.errors()
    rows = [("system gain (DN/e-)", result.gain_dn_per_e, result.gain_configured, e["gain"]),
            ("read noise (e-)", result.read_noise_e, result.read_noise_configured, e["read_noise"]),
            ("full well (e-)", result.full_well_e, result.full_well_configured, e["full_well"])]
    lines = [f"PTC {result.sensor} {pixel_format(result.pixel_format).fourcc.strip()} "
             f"{result.size[0]}x{result.size[1]}, {len(result.points)} pairs, flat level {result.level:.3f}",
             f"{'':<22}{'measured':>12}{'configured':>12}{'error':>9}"]
    lines += [f"{name:<22}{m:>12.5g}{c:>12.5g}{err:>+9.2%}" for name, m, c, err in rows]
    lines.append(f"EMVA saturation capacity (mean at max variance): {result.saturation_capacity_e:.0f} e-")
    lines.append(f"applied gain {result.applied_gain:g}" + ("; the plateau sits at the ADC's top code (the full "
                                                            "well is at least this)" if result.adc_limited else ""))
    return "\n".join(lines)
