"""`rollcam bench imu`: the IMU's noise against its configuration, and what gyro RS correction buys.

Allan: a static IMU is sampled for ``hours`` of device time; the overlapping Allan deviation of each axis is
fitted with Kalibr's two-term model ``sigma^2(tau) = N^2 / tau + K^2 tau / 3`` (white noise density N, bias
random walk K; weighted least squares on the curve) and compared with the configured figures.

Calibration: a capture of the ``ego=calib`` excitation (320x240, default IMU noise, a configured time offset)
goes through ``rollcam calibrate``'s estimator; the line time must come back within 1 % and the offset
within 0.1 ms.

Correction: ``benchmarks/imu_correction.py`` (gyro and flow correction against the GS frame of the same
instant). Timings are medians within one run.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

ALLAN_N_TOLERANCE, ALLAN_K_TOLERANCE = 0.10, 0.30
LINE_TIME_TOLERANCE, OFFSET_TOLERANCE_NS = 0.01, 100_000
CALIB_OFFSET_US = -1700
EGO_CASES = ("pan", "drone", "vehicle")


def allan_deviation(rate: np.ndarray, rate_hz: float, taus_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Overlapping Allan deviation of a rate signal (n, axes) at cluster times ``taus_s`` (rounded to whole
    samples, duplicates dropped); returns (taus, adev (taus, axes))."""
    x = np.asarray(rate, np.float64)
    x = x[:, None] if x.ndim == 1 else x
    theta = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0) / rate_hz])
    n = x.shape[0]
    ms = np.unique(np.clip(np.round(np.asarray(taus_s) * rate_hz).astype(np.int64), 1, (n - 1) // 2))
    out = np.empty((ms.size, x.shape[1]))
    for i, m in enumerate(ms):
        d = theta[2 * m:] - 2.0 * theta[m:-m] + theta[:-2 * m]
        tau = m / rate_hz
        out[i] = np.sqrt(np.sum(d * d, axis=0) / (2.0 * tau * tau * (n - 2 * m + 1)))
    return ms / rate_hz, out


def fit_allan(taus: np.ndarray, adev: np.ndarray) -> tuple[float, float]:
    """(N, K) of ``sigma^2 = N^2 / tau + K^2 tau / 3`` fitted to an Allan deviation (relative weights)."""
    var = np.asarray(adev, np.float64) ** 2
    a = np.stack([1.0 / taus, taus / 3.0], axis=1) / var[:, None]
    coef, *_ = np.linalg.lstsq(a, np.ones_like(var), rcond=None)
    return float(np.sqrt(max(coef[0], 0.0))), float(np.sqrt(max(coef[1], 0.0)))


def allan_study(hours: float = 2.0, rate_hz: int = 100, seed: int = 0) -> dict[str, Any]:
    """Allan fit of a static default IMU over ``hours`` of device time against its configured figures."""
    from rollcam.sim.imu import Imu, ImuParams
    from rollcam.sim.pose import Trajectory
    from rollcam.sim.scene import Camera

    p = ImuParams(rate_hz=rate_hz)
    imu = Imu(p, Trajectory(Camera("static", 64, 48, 4.0, 4.0, (0.0, 0.0, 1.0))), seed=seed)
    s = imu.samples(0, int(hours * 3600 * 1e9))
    taus = np.logspace(np.log10(2.0 / rate_hz), np.log10(hours * 3600 / 10), 40)
    out: dict[str, Any] = {"rate_hz": rate_hz, "hours": hours, "samples": len(s)}
    for name, data, n_cfg, k_cfg in (
            ("gyroscope", s.gyro, p.gyroscope_noise_density, p.gyroscope_random_walk),
            ("accelerometer", s.accel - s.accel.mean(axis=0), p.accelerometer_noise_density,
             p.accelerometer_random_walk)):
        tau, adev = allan_deviation(data, rate_hz, taus)
        fits = [fit_allan(tau, adev[:, i]) for i in range(3)]
        n_fit, k_fit = float(np.mean([f[0] for f in fits])), float(np.mean([f[1] for f in fits]))
        out[name] = {"noise_density": {"config": n_cfg, "fit": n_fit, "rel_error": n_fit / n_cfg - 1},
                     "random_walk": {"config": k_cfg, "fit": k_fit, "rel_error": k_fit / k_cfg - 1},
                     "per_axis": [{"N": f[0], "K": f[1]} for f in fits]}
    return out


def calibration_study(frames: int, size: tuple[int, int] = (320, 240)) -> dict[str, Any]:
    """``rollcam calibrate``'s estimate from a fresh ``ego=calib`` capture against its configuration."""
    import json
    import tempfile
    import time
    from pathlib import Path

    from rollcam.host.correction.calibrate import calibrate
    from rollcam.host.recording.capture import capture
    from rollcam.host.sources import open_camera

    uri = (f"emu:imx219?size={size[0]}x{size[1]}&ego=calib&pedestrians=0&exposure_us=2000"
           f"&imu_offset_us={CALIB_OFFSET_US}")
    with tempfile.TemporaryDirectory(prefix="rollcam-calib-") as tmp:
        with open_camera(uri) as src:
            capture(src, Path(tmp) / "cap", frames, progress=False)
        rec = json.loads((Path(tmp) / "cap" / "frames.jsonl").read_text().splitlines()[0])
        t0 = time.perf_counter()
        cal = calibrate(Path(tmp) / "cap")
        seconds = time.perf_counter() - t0
    line_ns, offset_ns = int(rec["line_time_ns"]), CALIB_OFFSET_US * 1000
    return {"uri": uri, "frames": frames, **cal.to_json(), "line_time_config_ns": line_ns,
            "offset_config_ns": offset_ns, "line_time_rel_error": cal.line_time_s * 1e9 / line_ns - 1,
            "offset_error_ns": cal.offset_s * 1e9 - offset_ns, "seconds": round(seconds, 2)}


def _target(value: float, op: str, limit: float) -> dict[str, Any]:
    ok = value <= limit if op == "<=" else value < limit
    return {"value": round(value, 4), "op": op, "limit": round(limit, 4), "pass": bool(ok)}


def run_imu_bench(*, quick: bool = False, detector: str | None = None,
                  say: Callable[[str], None] = lambda _: None) -> dict[str, Any]:
    """The three parts of the study as one JSON document, with its targets."""
    from .imu_correction import CASES, correction_case

    say("IMU noise: Allan deviation of a static IMU")
    allan = allan_study(hours=0.5 if quick else 2.0)
    say("calibration: line time and camera-IMU offset from an ego=calib capture")
    calib = calibration_study(16 if quick else 30)
    size, frames = ((640, 480), 2) if quick else ((1920, 1080), 4)
    det = None
    if detector:
        from rollcam.host.detectors import load_detector

        det = load_detector(detector)
    cases = {}
    for name, opts in CASES.items():
        say(f"RS correction: {name} at {size[0]}x{size[1]}")
        cases[name] = correction_case(opts, size, frames, det)
    targets = {}
    for sensor in ("gyroscope", "accelerometer"):
        for term, tol in (("noise_density", ALLAN_N_TOLERANCE), ("random_walk", ALLAN_K_TOLERANCE)):
            targets[f"allan_{sensor}_{term}_rel_error"] = _target(abs(allan[sensor][term]["rel_error"]), "<=", tol)
    targets["calibration_line_time_rel_error"] = _target(abs(calib["line_time_rel_error"]), "<=",
                                                         LINE_TIME_TOLERANCE)
    targets["calibration_offset_error_ns"] = _target(abs(calib["offset_error_ns"]), "<=", OFFSET_TOLERANCE_NS)
    for name in EGO_CASES:  # the gyro undoes camera rotation: less image and box error than uncorrected RS
        c = cases[name]
        targets[f"{name}_gyro_mae_below_rs"] = _target(c["mae_vs_gs"]["gyro"], "<", c["mae_vs_gs"]["rs"])
        targets[f"{name}_gyro_box_error_below_rs"] = _target(c["box_error_px"]["gyro"], "<",
                                                             c["box_error_px"]["rs"])
    c = cases["objects"]  # object motion: the flow's case (the gyro cannot help)
    targets["objects_flow_mae_below_rs"] = _target(c["mae_vs_gs"]["flow"], "<", c["mae_vs_gs"]["rs"])
    targets["objects_flow_box_error_below_rs"] = _target(c["box_error_px"]["flow"], "<", c["box_error_px"]["rs"])
    return {"allan": allan, "calibration": calib, "correction": {"size": list(size), "cases": cases},
            "targets": targets}


def format_report(doc: dict[str, Any]) -> str:
    """The plain-text report."""
    a = doc["allan"]
    lines = [f"Allan fit of a static IMU ({a['hours']} h at {a['rate_hz']} Hz, {a['samples']} samples):"]
    for sensor in ("gyroscope", "accelerometer"):
        for term in ("noise_density", "random_walk"):
            t = a[sensor][term]
            lines.append(f"  {sensor:13s} {term:13s} config {t['config']:.4e}  fit {t['fit']:.4e}  "
                         f"({t['rel_error'] * 100:+.1f} %)")
    cal = doc["calibration"]
    lines.append(f"calibration ({cal['frames']} frames of {cal['uri']}): line time {cal['line_time_ns']:.1f} +- "
                 f"{cal['line_time_std_ns']:.1f} ns (config {cal['line_time_config_ns']}, "
                 f"{cal['line_time_rel_error'] * 100:+.2f} %), offset {cal['timeshift_cam_imu_ns'] / 1e3:.1f} +- "
                 f"{cal['timeshift_cam_imu_std_ns'] / 1e3:.1f} us (config {cal['offset_config_ns'] / 1e3:.0f}, "
                 f"{cal['offset_error_ns'] / 1e3:+.1f} us), {cal['seconds']:.1f} s")
    c = doc["correction"]
    lines.append(f"RS correction at {c['size'][0]}x{c['size'][1]}, RS / gyro / flow (MAE 8-bit vs the GS frame of "
                 "the same instant; box error px vs GS boxes; ms per frame):")
    for name, r in c["cases"].items():
        mae = " / ".join(f"{r['mae_vs_gs'][m]:.2f}" for m in ("rs", "gyro", "flow"))
        box = " / ".join("-" if r["box_error_px"][m] is None else f"{r['box_error_px'][m]:.2f}"
                         for m in ("rs", "gyro", "flow"))
        rec = r.get("recall_vs_gs")
        extra = "" if rec is None else "  recall GS/RS/gyro/flow " + "/".join(
            "-" if v is None else f"{v:.2f}" for v in rec.values())
        lines.append(f"  {name:8s} MAE {mae}  box {box}  ms gyro {r['correct_ms']['gyro']:.0f} flow "
                     f"{r['correct_ms']['flow']:.0f}{extra}")
    return "\n".join(lines)
