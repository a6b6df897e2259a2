"""How the exact RS frame's cost grows (``rollcam bench render``): ms/frame against resolution and walker count.

For each camera (static, or moving with the ``vehicle`` ego-motion), frame size and walker count, the exact
per-line render of an RS frame is timed (median over frames at different indices, after a warm-up that builds
the static layer), in wall and in process CPU time. The fits state the growth on CPU time (on a loaded machine
wall time measures the scheduler): ms = a * megapixels^b per camera and walker count (b near 1 is cost in
proportion to pixels), and ms = c + d * walkers per camera and size (d: the cost of one more walker).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .cameras import camera

SENSOR = "letsroll"
CAMERAS = {"static": "none", "moving": "vehicle"}
"""Scaling camera name -> ego-motion preset."""


def _time_exact(w: int, h: int, walkers: int, ego: str, frames: int) -> tuple[float, float]:
    """(median wall ms, median process CPU ms) of an exact RS frame."""
    cam = camera(SENSOR, {"scene": "street", "speed": "normal", "pedestrians": walkers, "ego": ego}, size=(w, h))
    r, bc = cam.renderer, cam.settings.readout.by_column
    r.render_lines(cam.line_times_ns(0, "rolling"), by_column=bc)  # warm-up: static layer, compile
    wall, cpu = [], []
    for i in range(frames):
        times = cam.line_times_ns(10 + 7 * i, "rolling")
        c0, t0 = time.process_time(), time.perf_counter()
        r.render_lines(times, by_column=bc)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return 1e3 * float(np.median(wall)), 1e3 * float(np.median(cpu))


def _fit_power(mpx: Sequence[float], ms: Sequence[float]) -> dict[str, float] | None:
    """ms = a * mpx^b by least squares in log-log (None with fewer than two sizes)."""
    if len(mpx) < 2 or min(ms) <= 0:
        return None
    b, log_a = np.polyfit(np.log(mpx), np.log(ms), 1)
    return {"a_ms": round(float(np.exp(log_a)), 4), "b": round(float(b), 3)}


def _fit_line(walkers: Sequence[int], ms: Sequence[float]) -> dict[str, float] | None:
    """ms = c + d * walkers by least squares (None with fewer than two counts)."""
    if len(walkers) < 2:
        return None
    d, c = np.polyfit(np.asarray(walkers, float), np.asarray(ms, float), 1)
    return {"c_ms": round(float(c), 4), "d_ms_per_walker": round(float(d), 5)}


def scaling_table(sizes: Sequence[tuple[int, int]], walkers: Sequence[int], frames: int,
                  say: Callable[[str], None]) -> dict[str, Any]:
    """The timed grid and its fits."""
    rows = []
    for cam_name, ego in CAMERAS.items():
        for w, h in sizes:
            for n in walkers:
                say(f"scaling: {cam_name} {w}x{h}, {n} walkers")
                ms, cpu_ms = _time_exact(w, h, n, ego, frames)
                rows.append({"camera": cam_name, "size": f"{w}x{h}", "megapixels": round(w * h / 1e6, 4),
                             "walkers": n, "ms_per_frame": round(ms, 3), "cpu_ms_per_frame": round(cpu_ms, 3)})
    fits: dict[str, Any] = {"vs_pixels": {}, "vs_walkers": {}}
    for cam_name in CAMERAS:
        for n in walkers:
            sel = [r for r in rows if r["camera"] == cam_name and r["walkers"] == n]
            fits["vs_pixels"][f"{cam_name}, {n} walkers"] = _fit_power([r["megapixels"] for r in sel],
                                                                       [r["cpu_ms_per_frame"] for r in sel])
        for w, h in sizes:
            sel = [r for r in rows if r["camera"] == cam_name and r["size"] == f"{w}x{h}"]
            fits["vs_walkers"][f"{cam_name}, {w}x{h}"] = _fit_line([r["walkers"] for r in sel],
                                                                   [r["cpu_ms_per_frame"] for r in sel])
    return {"rows": rows, "fits": fits, "frames": frames,
            "what": "exact RS frame (render_lines with the RS line times), median of the timed frames; fits on "
                    "process CPU ms: ms = a * megapixels^b per camera and walker count, ms = c + d * walkers per "
                    "camera and size"}


def format_scaling(doc: dict[str, Any]) -> list[str]:
    """The grid as a table (ms/frame, rows: camera and size, columns: walker counts) and the fits."""
    rows = doc["rows"]
    walkers = sorted({r["walkers"] for r in rows})
    head = f"{'camera':<8}{'size':>11}" + "".join(f"{f'{n} walkers':>13}" for n in walkers)
    out = ["scaling (exact RS, ms/frame wall; CPU ms in brackets):", head]
    for cam_name in CAMERAS:
        for size in dict.fromkeys(r["size"] for r in rows):
            cells = {r["walkers"]: r for r in rows if r["camera"] == cam_name and r["size"] == size}
            out.append(f"{cam_name:<8}{size:>11}" + "".join(
                f"{cells[n]['ms_per_frame']:>7.1f} ({cells[n]['cpu_ms_per_frame']:>4.0f})" for n in walkers))
    for name, fit in doc["fits"]["vs_pixels"].items():
        if fit:
            out.append(f"fit {name}: CPU ms = {fit['a_ms']:.3g} * MP^{fit['b']:.2f}")
    for name, fit in doc["fits"]["vs_walkers"].items():
        if fit:
            out.append(f"fit {name}: CPU ms = {fit['c_ms']:.3g} + {fit['d_ms_per_walker']:.3g} * walkers")
    return out
