"""Photon transfer curve of an emulated sensor, measured from its frames alone: ``rollcam bench ptc``.

The EMVA 1288 (release 4.0) method on ``emu:SENSOR?scene=flat&level=L&format=RAW`` frames at 1 fps, so the
exposure reaches about a second and dark current shows: at each of a series of exposures a pair of dark
frames (``level=0``) and a pair of flat-field frames, and stacks of ``DARK_STACK`` dark and flat-field
frames at the exposure of about half saturation. For each pair the mean ``mean(A + B) / 2`` and the
temporal variance ``var(A - B) / 2`` (the difference cancels DSNU and PRNU); the bright pair's signal
above dark is ``mu = mu_bright - mu_dark`` and ``var = var_bright - var_dark`` at the same exposure. Then:

- system gain K (DN/e-): slope of var against mu through the origin, on points below 70% of saturation,
  divided by the gain the frames' metadata records (a sensor whose minimum analog gain exceeds 1 cannot
  run at unity), so it compares with the configured K at unity gain;
- read noise (e-): sqrt(var_dark - 1/12) / (K * g) from a dark pair at the shortest exposure and the
  sensor's highest analog gain g (1/12 DN^2 is the ADC's quantisation, a correction that holds only while
  the read noise spans a DN or more: at unity gain a low-gain sensor's read noise is a fraction of a DN);
- saturation: EMVA's saturation point is the mean at maximum variance; the full well is the plateau, the
  largest mean above dark, over K at the applied gain (``adc_limited`` when the plateau is the ADC's top
  code rather than the full well);
- dark current (e-/s): slope of the dark mean against exposure (a line with offset) over K (EMVA's
  ``mu_I.mean``);
- DSNU (e-): the spatial variance of the dark stack's mean image less its temporal part,
  ``s2 = var_spatial(mean image) - mean(var_temporal) / L``, as sqrt(s2) / K (EMVA's ``DSNU_1288``).

Frames are read through ``open_camera``, as any capture would be; the configured figures come from the
sensor's YAML only to print the comparison. ``capture_emva`` returns the frames themselves, so another
analysis (the EMVA 1288 reference implementation, in the tests) can run on the same captures.
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
DARK_STACK = 16
"""Dark frames averaged for the DSNU (EMVA 1288's L)."""
CAPTURE_FPS = 1.0
"""Frame rate of every capture: a 1 s frame lets the exposure reach about 1 s, where dark current shows."""


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
    dsnu_e: float
    dsnu_configured: float
    dark_current_e_per_s: float
    dark_current_configured: float
    points: list[dict[str, float]]

    def errors(self) -> dict[str, float]:
        """Relative errors (measured / configured - 1) of gain, read noise, full well, DSNU and dark current."""
        def rel(a: float, b: float) -> float:
            return a / b - 1.0 if b else (0.0 if a == 0 else math.inf)

        return {"gain": rel(self.gain_dn_per_e, self.gain_configured),
                "read_noise": rel(self.read_noise_e, self.read_noise_configured),
                "full_well": rel(self.full_well_e, self.full_well_configured),
                "dsnu": rel(self.dsnu_e, self.dsnu_configured),
                "dark_current": rel(self.dark_current_e_per_s, self.dark_current_configured)}

    def to_json(self) -> dict[str, Any]:
        """Plain-JSON form (``ptc.json``)."""
        doc = asdict(self)
        doc["errors"] = self.errors()
        return doc


@dataclass
class EmvaPoint:
    """One exposure of the series: a dark pair and a flat-field pair, samples in DN (float64)."""

    exposure_ns: int
    gain: float  # total gain the frames' metadata records
    dark: tuple[np.ndarray, np.ndarray]
    bright: tuple[np.ndarray, np.ndarray]


@dataclass
class EmvaCaptures:
    """The frames of one EMVA 1288 measurement of an emulated sensor, as ``open_camera`` delivered them."""

    sensor: str
    pixel_format: str
    size: tuple[int, int]
    level: float
    points: list[EmvaPoint]  # by exposure
    dark_stack: np.ndarray  # (DARK_STACK, h, w) dark frames at ``stack_exposure_ns``
    bright_stack: np.ndarray  # as many flat-field frames at the same exposure (EMVA's spatial set)
    stack_exposure_ns: int
    read_pair: tuple[np.ndarray, np.ndarray]  # dark pair at the shortest exposure and the highest analog gain
    read_gain: float


def _raw_format(sensor_name: str) -> str:
    """The sensor's unpacked raw format at its full ADC depth (what a PTC measures on)."""
    s = load_sensor(sensor_name)
    return bayer_fourcc(s.bayer_order, s.bit_depth) if s.bayer_order != "mono" else \
        {8: "GREY", 10: "Y10 ", 12: "Y12 ", 16: "Y16 "}[s.bit_depth]


def _frames(uri: str, width: int, n: int = 2) -> tuple[list[np.ndarray], int, float]:
    """``n`` frames of ``uri`` as float samples, their exposure and the total gain their metadata records."""
    from rollcam.host import open_camera

    with open_camera(uri) as cam:
        frames = [cam.read() for _ in range(n)]
    assert all(f is not None for f in frames)
    out = [codec(f.format).decode(f.data, width, f.height).astype(np.float64) for f in frames]
    a = frames[0]
    return out, int(a.exposure_ns), float(a.meta["analog_gain"] * a.meta["digital_gain"])


def _stats(fa: np.ndarray, fb: np.ndarray) -> tuple[float, float]:
    return float((fa.mean() + fb.mean()) / 2), float(np.var(fa - fb) / 2)


def capture_emva(sensor: str = "imx219", *, size: tuple[int, int] = (256, 192), steps: int = 24,
                 level: float | None = None, serial: str = "ptc", seed: int = 0) -> EmvaCaptures:
    """Capture the EMVA 1288 data set of ``emu:sensor`` (see the module docstring).

    ``steps`` exposures from the shortest to the longest the sensor allows at ``CAPTURE_FPS``, then a third as
    many again around the variance peak; ``level`` is the flat field's radiance (default: saturating at
    about 60% of the longest exposure).
    """
    if steps < 4:
        raise ConfigError(f"a PTC needs at least 4 exposure steps, got {steps!r}")
    cfg = load_sensor(sensor)
    fourcc = _raw_format(sensor)
    w, h = size
    base = (f"emu:{sensor}?scene=flat&format={fourcc.strip()}&size={w}x{h}&serial={serial}&blur_px=0"
            f"&fps={CAPTURE_FPS:g}")
    # The exposure range the sensor allows at this size: ask for 0 and for far too long, get both clamps.
    from rollcam.host import open_camera

    with open_camera(base + "&exposure_us=0") as c:
        t_min = c.camera.settings.exposure_ns
    with open_camera(base + "&exposure_us=1e9") as c:
        t_max = c.camera.settings.exposure_ns
    if level is None:
        level = REFERENCE_EXPOSURE_S / (0.6 * t_max * 1e-9)
    points: list[EmvaPoint] = []

    def measure(exposures: np.ndarray) -> None:
        for t_want in exposures:
            i = len(points)
            exp = f"&exposure_us={t_want / 1000:.3f}&noise_seed={seed + 1 + 2 * i}"
            (ba, bb), t, gain = _frames(f"{base}&level={level}{exp}", w)
            (da, db), _, _ = _frames(f"{base}&level=0{exp}", w)
            points.append(EmvaPoint(t, gain, (da, db), (ba, bb)))

    measure(np.linspace(t_min, t_max, steps))
    # Refine around the variance peak (EMVA's saturation point) with a third as many steps again.
    var = [_stats(*p.bright)[1] - _stats(*p.dark)[1] for p in points]
    i_peak = int(np.argmax(var))
    lo, hi = points[max(i_peak - 1, 0)].exposure_ns, points[min(i_peak + 1, len(points) - 1)].exposure_ns
    measure(np.linspace(lo, hi, max(steps // 3, 2) + 2)[1:-1])
    points.sort(key=lambda p: p.exposure_ns)
    # The spatial set at about half saturation, as EMVA 1288 takes it.
    stats = np.array([np.subtract(_stats(*p.bright), _stats(*p.dark)) for p in points])
    mu_sat = stats[int(np.argmax(stats[:, 1])), 0]
    t_half = points[int(np.argmin(np.abs(stats[:, 0] - 0.5 * mu_sat)))].exposure_ns
    stack_uri = f"{base}&exposure_us={t_half / 1000}&noise_seed={seed}"
    stack, t_stack, _ = _frames(stack_uri + "&level=0", w, DARK_STACK)
    bright, _, _ = _frames(stack_uri + f"&level={level}", w, DARK_STACK)
    read, _, g_read = _frames(f"{base}&level=0&exposure_us={t_min / 1000}&gain={cfg.gain.analog_max}"
                              f"&noise_seed={seed}", w)
    return EmvaCaptures(sensor, fourcc, (w, h), float(level), points, np.stack(stack), np.stack(bright), t_stack,
                        (read[0], read[1]), g_read)


def dark_current_dn_per_s(exposures_ns: np.ndarray, dark_means_dn: np.ndarray) -> float:
    """EMVA 1288 dark current in DN/s: the slope of the dark mean against exposure (a fitted line)."""
    slope, _ = np.polyfit(np.asarray(exposures_ns, np.float64) * 1e-9, np.asarray(dark_means_dn), 1)
    return float(slope)


def dsnu_dn(stack: np.ndarray) -> float:
    """EMVA 1288 DSNU in DN from L dark frames: spatial variance of their mean less its temporal part."""
    n = stack.shape[0]
    s2_measured = float(np.var(stack.mean(axis=0), ddof=1))
    s2_stack = float(np.var(stack, axis=0, ddof=1).mean())
    return math.sqrt(max(s2_measured - s2_stack / n, 0.0))


def analyse_emva(c: EmvaCaptures) -> PtcResult:
    """The figures of ``c`` by the EMVA 1288 formulas (see the module docstring)."""
    cfg = load_sensor(c.sensor)
    points: list[dict[str, float]] = []
    dark_means = []
    for p in c.points:
        (mean, var), (md, vd) = _stats(*p.bright), _stats(*p.dark)
        dark_means.append(md)
        points.append({"exposure_ns": p.exposure_ns, "mean_dn": mean - md, "var_dn2": var - vd, "mean_raw_dn": mean,
                       "dark_mean_dn": md, "dark_var_dn2": vd})
    gain = c.points[-1].gain
    mu = np.array([p["mean_dn"] for p in points])
    var = np.array([p["var_dn2"] for p in points])
    i_sat = int(np.argmax(var))
    lin = (mu > 0) & (mu <= LINEAR_FRACTION * mu[i_sat])
    if lin.sum() < 2:
        raise ConfigError(f"PTC of {c.sensor!r}: fewer than 2 points below {LINEAR_FRACTION:.0%} of saturation; "
                          "use more steps or a lower level")
    k = float(np.sum(mu[lin] * var[lin]) / np.sum(mu[lin] ** 2))
    read_e = math.sqrt(max(_stats(*c.read_pair)[1] - 1 / 12, 0.0)) / (k * c.read_gain / gain)
    dark_e_s = dark_current_dn_per_s(np.array([p.exposure_ns for p in c.points]), np.array(dark_means)) / k
    n = cfg.noise
    # The plateau reached the ADC's top code before the full well: the sensor cannot show its full well.
    adc_limited = max(p["mean_raw_dn"] for p in points) > (1 << cfg.bit_depth) - 1.5
    return PtcResult(
        sensor=c.sensor, pixel_format=c.pixel_format, size=c.size, level=c.level, applied_gain=gain,
        gain_dn_per_e=k / gain, gain_configured=n.system_gain_dn_per_e, read_noise_e=read_e,
        read_noise_configured=n.dark_noise_e, full_well_e=float(mu.max()) / k, full_well_configured=n.full_well_e,
        saturation_capacity_e=float(mu[i_sat]) / k, adc_limited=adc_limited, dsnu_e=dsnu_dn(c.dark_stack) / k,
        dsnu_configured=n.dsnu_e, dark_current_e_per_s=dark_e_s, dark_current_configured=n.dark_current_e_per_s,
        points=points)


def measure_ptc(sensor: str = "imx219", *, size: tuple[int, int] = (256, 192), steps: int = 24,
                level: float | None = None, serial: str = "ptc", seed: int = 0) -> PtcResult:
    """Run the photon transfer measurement on ``emu:sensor`` (see the module docstring)."""
    return analyse_emva(capture_emva(sensor, size=size, steps=steps, level=level, serial=serial, seed=seed))


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
    from rollcam.common.files import write_figure

    write_figure(path, fig, dpi=110)


def run_ptc(sensor: str, out_dir: str | Path) -> PtcResult:
    """``rollcam bench ptc``: measure, write ``ptc.json`` and ``ptc.png`` under ``out_dir``."""
    import json

    from rollcam.common.files import write_atomic

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    result = measure_ptc(sensor)
    write_atomic(out / "ptc.json", json.dumps(result.to_json(), indent=1).encode())
    plot_ptc(result, out / "ptc.png")
    return result


def format_ptc(result: PtcResult) -> str:
    """The comparison table ``rollcam bench ptc`` prints."""
    e = result.errors()
    rows = [("system gain (DN/e-)", result.gain_dn_per_e, result.gain_configured, e["gain"]),
            ("read noise (e-)", result.read_noise_e, result.read_noise_configured, e["read_noise"]),
            ("full well (e-)", result.full_well_e, result.full_well_configured, e["full_well"]),
            ("DSNU (e-)", result.dsnu_e, result.dsnu_configured, e["dsnu"]),
            ("dark current (e-/s)", result.dark_current_e_per_s, result.dark_current_configured,
             e["dark_current"])]
    lines = [f"PTC {result.sensor} {pixel_format(result.pixel_format).fourcc.strip()} "
             f"{result.size[0]}x{result.size[1]}, {len(result.points)} pairs, flat level {result.level:.3f}",
             f"{'':<22}{'measured':>12}{'configured':>12}{'error':>9}"]
    lines += [f"{name:<22}{m:>12.5g}{c:>12.5g}{err:>+9.2%}" for name, m, c, err in rows]
    lines.append(f"EMVA saturation capacity (mean at max variance): {result.saturation_capacity_e:.0f} e-")
    lines.append(f"applied gain {result.applied_gain:g}" + ("; the plateau sits at the ADC's top code (the full "
                                                            "well is at least this)" if result.adc_limited else ""))
    return "\n".join(lines)
