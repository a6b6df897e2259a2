"""`rollcam bench imu`: the IMU's noise against its configuration, and what gyro RS correction buys.

Allan: a static IMU is sampled for ``hours`` of device time; the overlapping Allan deviation of each axis is
fitted with Kalibr's two-term model ``sigma^2(tau) = N^2 / tau + K^2 tau / 3`` (white noise density N, bias
random walk K; weighted least squares on the curve) and compared with the configured figures.

Correction: for ego-motion cases (camera panning, a drone's rotation and vibration, a vehicle) and one of
object motion only (a static camera, fast walkers), frame pairs of the same instant are rendered under
both shutters; the RS frame is corrected from the device's gyro (``rollcam.sim.rscorrect``) and compared with
the GS frame: mean absolute error (8-bit, pixels whose source lies inside the frame), box error (mean
absolute edge offset from the GS box, px: the RS box as rendered, and as the correction maps it), the
correction's time per frame, and optionally the recall of a detector against the GS boxes on GS, RS and
corrected RS (the study's two pipelines side by side). Timings are medians within one run.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

CASES = {"pan": "ego=pan&pedestrians=12", "drone": "ego=drone&pedestrians=12",
         "vehicle": "ego=vehicle&pedestrians=12", "objects": "ego=none&speed=fast&pedestrians=12"}
"""Case name -> emu: options: camera motion in the first three, object motion only in the last."""
ALLAN_N_TOLERANCE, ALLAN_K_TOLERANCE = 0.10, 0.30


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


def _box_error(a: Any, b: Any) -> float:
    return float(np.mean(np.abs(np.subtract(a, b))))


def _mapped_box(box: Any, rot: np.ndarray, k: tuple, w: int, h: int) -> tuple[float, float, float, float]:
    from rollcam.sim.rscorrect import forward_points

    x0, y0, x1, y1 = box
    s = np.linspace(0.0, 1.0, 16)
    # x extents are continuous (pixel i spans [i, i + 1)), y whole rows: both to OpenCV's pixel-centre coordinates
    xa, xb, ya, yb = x0 - 0.5, x1 - 0.5, y0, y1 - 1
    pts = np.concatenate([np.stack([xa + (xb - xa) * s, np.full_like(s, ya)], 1),
                          np.stack([xa + (xb - xa) * s, np.full_like(s, yb)], 1),
                          np.stack([np.full_like(s, xa), ya + (yb - ya) * s], 1),
                          np.stack([np.full_like(s, xb), ya + (yb - ya) * s], 1)])
    m = forward_points(pts, rot, k)
    return (max(m[:, 0].min() + 0.5, 0.0), max(m[:, 1].min(), 0.0), min(m[:, 0].max() + 0.5, w),
            min(m[:, 1].max() + 1, h))


def correction_case(options: str, size: tuple[int, int], frames: int, detector: Any = None) -> dict[str, Any]:
    """One case of the correction study (see the module docstring)."""
    from rollcam.host import open_camera
    from rollcam.host.truthmatch import RunningPR
    from rollcam.sim.rscorrect import gyro_line_rotations, unwarp

    w, h = size
    uri = f"emu:imx219?size={w}x{h}&imu=on&{options}"
    src = open_camera(uri)
    mae_rs, mae_c, box_rs, box_c, ms = [], [], [], [], []
    pr = {k: RunningPR() for k in ("gs", "rs", "corrected")}
    for _ in range(frames):
        gs, rs = src.read_pair()
        p = rs.imu.params
        times = rs.row_times_ns
        imu = src.device.imager.imu.imu(src.spec, src.camera.camera)
        cover = imu.samples(int(times.min()) + p.time_offset_ns - 10**7, int(times.max()) + p.time_offset_ns + 10**7)
        k = tuple(rs.meta["intrinsics"])
        t0 = time.perf_counter()
        rot = gyro_line_rotations(cover, times, int(times.min()))
        out, valid = unwarp(rs.data, rot, k)
        ms.append((time.perf_counter() - t0) * 1e3)
        g, r, c = (x.astype(np.int16) for x in (gs.data, rs.data, out))
        mae_rs.append(float(np.abs(g - r)[valid].mean()))
        mae_c.append(float(np.abs(g - c)[valid].mean()))
        for o in rs.objects or ():
            if o.box_gs is not None and o.box_rs is not None and o.visible > 0.5:
                box_rs.append(_box_error(o.box_rs, o.box_gs))
                box_c.append(_box_error(_mapped_box(o.box_rs, rot, k, w, h), o.box_gs))
        if detector is not None:
            for name, f, img in (("gs", gs, gs.data), ("rs", rs, rs.data), ("corrected", rs, out)):
                pr[name].update(f, detector.detect(img))
    doc: dict[str, Any] = {
        "uri": uri, "frames": frames, "mae_rs_vs_gs": float(np.mean(mae_rs)),
        "mae_corrected_vs_gs": float(np.mean(mae_c)),
        "box_error_rs_px": float(np.mean(box_rs)) if box_rs else None,
        "box_error_corrected_px": float(np.mean(box_c)) if box_c else None,
        "boxes": len(box_rs), "correct_ms": float(np.median(ms))}
    if detector is not None:  # recall against the GS boxes: what each pipeline's detector sees
        doc["recall_vs_gs"] = {k: v.totals["gs"].recall for k, v in pr.items()}
    return doc


def run_imu_bench(*, quick: bool = False, detector: str | None = None,
                  say: Callable[[str], None] = lambda _: None) -> dict[str, Any]:
    """Both halves of the study as one JSON document, with its targets."""
    say("IMU noise: Allan deviation of a static IMU")
    allan = allan_study(hours=0.5 if quick else 2.0)
    size, frames = ((640, 480), 2) if quick else ((1920, 1080), 4)
    det = None
    if detector:
        from rollcam.host.detectors import load_detector

        det = load_detector(detector)
    cases = {}
    for name, opts in CASES.items():
        say(f"gyro correction: {name} at {size[0]}x{size[1]}")
        cases[name] = correction_case(opts, size, frames, det)
    targets = {}
    for sensor in ("gyroscope", "accelerometer"):
        for term, tol in (("noise_density", ALLAN_N_TOLERANCE), ("random_walk", ALLAN_K_TOLERANCE)):
            err = allan[sensor][term]["rel_error"]
            targets[f"allan_{sensor}_{term}_rel_error"] = {"value": round(abs(err), 4), "op": "<=", "limit": tol,
                                                           "pass": abs(err) <= tol}
    pan = cases["pan"]
    targets["pan_corrected_mae_below_rs"] = {"value": round(pan["mae_corrected_vs_gs"], 3), "op": "<",
                                             "limit": round(pan["mae_rs_vs_gs"], 3),
                                             "pass": pan["mae_corrected_vs_gs"] < pan["mae_rs_vs_gs"]}
    return {"allan": allan, "correction": {"size": list(size), "cases": cases}, "targets": targets}


def format_report(doc: dict[str, Any]) -> str:
    """The plain-text report."""
    a = doc["allan"]
    lines = [f"Allan fit of a static IMU ({a['hours']} h at {a['rate_hz']} Hz, {a['samples']} samples):"]
    for sensor in ("gyroscope", "accelerometer"):
        for term in ("noise_density", "random_walk"):
            t = a[sensor][term]
            lines.append(f"  {sensor:13s} {term:13s} config {t['config']:.4e}  fit {t['fit']:.4e}  "
                         f"({t['rel_error'] * 100:+.1f} %)")
    c = doc["correction"]
    lines.append(f"gyro RS correction at {c['size'][0]}x{c['size'][1]} (MAE 8-bit vs the GS frame of the same "
                 "instant; box error px vs GS boxes):")
    for name, r in c["cases"].items():
        box = ("-" if r["box_error_rs_px"] is None else
               f"{r['box_error_rs_px']:.2f} -> {r['box_error_corrected_px']:.2f}")
        rec = r.get("recall_vs_gs")
        extra = "" if rec is None else "  recall GS/RS/corr " + "/".join(
            "-" if v is None else f"{v:.2f}" for v in rec.values())
        lines.append(f"  {name:8s} MAE RS {r['mae_rs_vs_gs']:.2f} -> corrected {r['mae_corrected_vs_gs']:.2f}  "
                     f"box {box}  {r['correct_ms']:.1f} ms/frame{extra}")
    return "\n".join(lines)
