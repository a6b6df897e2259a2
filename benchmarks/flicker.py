"""Modulated light: ``rollcam bench flicker``, the cost of flicker on and its bands against the analytic values.

Cost: a night street (20 walkers, static camera, sodium lamps on 50 Hz mains and PWM LED signs), one RS frame
after another with the lamps off and on, interleaved in one run so the machine's load falls on both alike, for
the 8-bit render path (``format=BGR3``) and the sensor path (RG10 raw, exposure integration with the default
motion-blur bound). Flicker on renders the scene once per light (steady light, lamps, signs) and joins them per
line, so its cost is about (1 + lights) renders plus one pass over the frame.

Accuracy: the flicker calibration scene (a wall under one lamp) on a rolling shutter; the band period in rows and
the Michelson contrast of the row profile are measured from the linear frame and compared with
``1 / (f * line_time)`` and, for a filament lamp's ``1 + d cos`` light, ``d * |sinc(f * exposure)|``.
Targets: period within 1 row and contrast within 2 % (plus 0.001 absolute, the k / f cases) of the analytic.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

LINE_PCK = 3448 * 5  # imx219 lines of 94.5 us: ~106 rows per 100 Hz band, four and a half bands in 480 rows
EXPOSURES_MS = (1.0, 3.0, 7.0, 10.0)
DEPTH = 0.5


def _time_frames(cams: dict[str, Any], frames: int) -> dict[str, float]:
    """Median CPU-wall ms per frame of each camera, frames interleaved across the cameras."""
    times: dict[str, list[float]] = {k: [] for k in cams}
    for cam in cams.values():
        cam.frame(0)  # warm-up: compile, static layers
    for i in range(1, frames + 1):
        for k, cam in cams.items():
            t0 = time.perf_counter()
            cam.frame(i)
            times[k].append((time.perf_counter() - t0) * 1e3)
    return {k: float(np.median(v)) for k, v in times.items()}


def cost(size: tuple[int, int], frames: int, say: Any = print) -> dict[str, Any]:
    """Per-frame ms with the lamps off and on, 8-bit path and sensor path, and the on/off ratios."""
    from .cameras import camera

    w, h = size
    cams = {}
    for lamps in ("off", "on"):
        night = {"scene": "street", "time": "night", "lamps": lamps}
        cams[f"bgr_{lamps}"] = camera("imx219", night, size=size, exposure_ns=4_000_000)
        cams[f"raw_{lamps}"] = camera("imx219", night, size=size, exposure_ns=4_000_000, pixel_format="RG10")
    say(f"flicker cost: {w}x{h} night street, {frames} frames per case")
    ms = _time_frames(cams, frames)
    n_lights = len(cams["bgr_on"].scene.lights)
    return {"size": f"{w}x{h}", "frames": frames, "lights": n_lights, "ms": {k: round(v, 2) for k, v in ms.items()},
            "ratio_bgr": round(ms["bgr_on"] / ms["bgr_off"], 2), "ratio_raw": round(ms["raw_on"] / ms["raw_off"], 2)}


def accuracy() -> list[dict[str, Any]]:
    """Band period and contrast of the flicker scene against the analytic values, per exposure."""
    from .cameras import camera

    wall = {"scene": "flicker", "lamp": "incandescent", "lamp_depth": DEPTH}
    rows_out, f = [], 0.0
    for exp_ms in EXPOSURES_MS:
        cam = camera("imx219", wall, size=(640, 480), line_length_pck=LINE_PCK, exposure_ns=round(exp_ms * 1e6))
        f = cam.scene.lights[0].waveform.freq_hz
        prof = cam.renderer.render_lines(cam.line_times_ns(0), linear=True).linear[:, :, 1].mean(axis=1)
        prof = prof.astype(np.float64)
        e_ns, lt_ns = cam.settings.exposure_ns, cam.settings.timing.line_time_ns
        x = f * e_ns * 1e-9
        want_c = DEPTH * abs(math.sin(math.pi * x) / (math.pi * x))
        got_c = float((prof.max() - prof.min()) / (prof.max() + prof.min()))
        want_p = 1e9 / (f * lt_ns)
        got_p = _period_rows(prof) if want_c > 0.02 else None
        rows_out.append({"exposure_ms": round(e_ns / 1e6, 4), "period_rows": None if got_p is None else round(got_p, 3),
                         "period_rows_analytic": round(want_p, 3), "contrast": round(got_c, 5),
                         "contrast_analytic": round(want_c, 5),
                         "ok": abs(got_c - want_c) <= 0.02 * want_c + 1e-3
                         and (got_p is None or abs(got_p - want_p) <= 1.0)})
    return rows_out


def _period_rows(p: np.ndarray) -> float:
    mid = 0.5 * (p.max() + p.min())
    up = np.flatnonzero((p[:-1] < mid) & (p[1:] >= mid))
    x = up + (mid - p[up]) / (p[up + 1] - p[up])
    return float(np.diff(x).mean()) if x.size >= 2 else float("nan")


def run_flicker_bench(size: tuple[int, int] = (1920, 1080), frames: int = 10, say: Any = print) -> dict[str, Any]:
    """The study's JSON document (cost, accuracy, targets)."""
    acc = accuracy()
    doc = {"cost": cost(size, frames, say), "accuracy": acc}
    bad = sum(not r["ok"] for r in acc)
    doc["targets"] = {"bands_match_analytic": {"value": len(acc) - bad, "op": "==", "limit": len(acc),
                                               "pass": bad == 0}}
    return doc


def format_report(doc: dict[str, Any]) -> str:
    """Plain-text report."""
    c = doc["cost"]
    ms = c["ms"]
    lines = [f"flicker cost, {c['size']} night street RS, {c['lights']} modulated lights, median of {c['frames']} "
             f"frames (one run, interleaved):",
             f"  8-bit (BGR3):        off {ms['bgr_off']:8.1f} ms   on {ms['bgr_on']:8.1f} ms   x{c['ratio_bgr']}",
             f"  sensor (RG10, blur): off {ms['raw_off']:8.1f} ms   on {ms['raw_on']:8.1f} ms   x{c['ratio_raw']}",
             "bands on the flicker wall (100 Hz filament light, depth 0.5) vs analytic:"]
    for r in doc["accuracy"]:
        per = "   -  " if r["period_rows"] is None else f"{r['period_rows']:7.2f}"
        lines.append(f"  exposure {r['exposure_ms']:7.3f} ms: period {per} rows (analytic "
                     f"{r['period_rows_analytic']:.2f}), contrast {r['contrast']:.4f} (analytic "
                     f"{r['contrast_analytic']:.4f}) {'ok' if r['ok'] else 'MISS'}")
    return "\n".join(lines)
