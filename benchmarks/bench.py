"""Speed versus error of the ways to make a rolling-shutter frame: ``rollcam bench render``.

On the study's camera (``letsroll``: 1920x1080, line time 1/32,400 s, 30 fps) and seeded streets with 20
pedestrians (static camera or ``vehicle`` ego-motion, normal or fast walkers), each method makes the RS frame
of the same instants and is timed (``time.perf_counter``, after a warm-up, median over frames at different
indices) and scored against the brute-force reference:

- ``reference``: the study's method, one full render per line keeping line r of render r (``Renderer.
  reference_lines``); its image is the error baseline.
- ``exact``: the per-line renderer called with the RS line times (the fast path).
- ``gs``: one global-shutter frame (the RS/GS cost ratio; its error is the RS effect itself).
- ``banded_K``: the line times quantised into K bands, each at its middle instant (K=1: a GS frame at
  mid-readout standing in for the RS frame).
- ``footage_F_METHOD``: GS footage at F fps rendered over one RS readout, then composed into the RS frame
  (``compose_rs`` nearest / linear / flow). Only the composition is timed; rendering the footage is its
  input (``input_ms``). Footage frame 0 is at the RS frame's first line. At the line rate (32,400 fps)
  every line is a footage frame: the study's method, whose renders are the reference's own, so they are
  shared. Flow runs with ``flow_preset='fast', flow_margin_px=48`` (full-frame DIS at 1080p costs seconds).

Errors: ``mean_abs_err_dn`` / ``max_abs_err_dn`` over every pixel and channel against the baseline image;
``max_box_err_px`` the worst coordinate difference, over pedestrians, between the method's RS boxes and the
exact RS boxes (composed frames use the ground truth of the footage frame each row was taken from; blended
rows have none, so linear and flow report null). The floor is one plain copy of a frame (``np.copyto``
into a preallocated array, median of many); every row reports its cost as a multiple of it.

``rollcam bench render --quick`` (under a minute once numba's cache is warm; a cold cache adds about 100 s of
CPU time compiling) runs two scenes and fewer methods and frames. Its reference is timed on every 27th line's full
render (every 108th with ego-motion) and scaled to all lines, and its error baseline is the exact per-line
image: that the exact path equals the reference is checked on the full image of each scene at 192x108 and on
the sampled lines at full size.

This module is the runner (the frame-copy floor, the targets, the JSON document); each scene's cases and
their error checks are ``rollcam.benchmarks.render_cases``.
"""

from __future__ import annotations

import dataclasses
import json
import os
import platform
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from rollcam.sim.hwconfig import load_sensor

from .render_cases import LINE_RATE, SCENES, SENSOR, BenchConfig, SceneBench, make_config
from .render_scaling import scaling_table


# ------------------------------------------------------------------------------------------------ floor
def memcpy_floor(height: int, width: int, repeats: int = 200) -> dict[str, Any]:
    """Median time of one plain frame copy (``np.copyto`` into a preallocated array), the physical floor.

    A 6 MB frame stays in a large last-level cache between repeats; ``cold_ms`` copies through a pool of
    frames larger than any cache, the DRAM-bound figure, for comparison.
    """
    rng = np.random.default_rng(0)
    src = rng.integers(0, 256, (height, width, 3), dtype=np.uint8)
    dst = np.empty_like(src)
    warm, warm_cpu = [], []
    for _ in range(repeats):
        c0, t0 = time.thread_time(), time.perf_counter()
        np.copyto(dst, src)
        warm.append(time.perf_counter() - t0)
        warm_cpu.append(time.thread_time() - c0)
    n_pool = max(2, -(-(128 << 20) // (2 * src.nbytes)))  # src + dst pool of >= 128 MB
    pool = [(np.full_like(src, i % 256), np.empty_like(src)) for i in range(n_pool)]
    for a, b in pool:
        np.copyto(b, a)  # fault the pages in
    cold, cold_cpu = [], []
    for i in range(max(repeats // 4, 2 * n_pool)):
        a, b = pool[i % n_pool]
        c0, t0 = time.thread_time(), time.perf_counter()
        np.copyto(b, a)
        cold.append(time.perf_counter() - t0)
        cold_cpu.append(time.thread_time() - c0)
    ms = 1e3 * float(np.median(warm))
    return {"what": f"np.copyto of a {width}x{height}x3 uint8 frame into a preallocated one",
            "bytes": int(src.nbytes), "ms": ms, "gb_per_s": src.nbytes / ms / 1e6, "repeats": repeats,
            "cold_ms": 1e3 * float(np.median(cold)), "cpu_ms": 1e3 * float(np.median(warm_cpu)),
            "cold_cpu_ms": 1e3 * float(np.median(cold_cpu))}


# ------------------------------------------------------------------------------------------- targets
STATIC_X_MEMCPY = 8.0
"""Largest exact static-camera RS frame time, in frame copies of the same run (warm and cold each)."""


def evaluate_targets(rows: list[dict[str, Any]], checks: dict[str, dict[str, Any]],
                     frame_period_ms: float) -> dict[str, dict[str, Any]]:
    """The project's speed and fidelity targets, from this run's numbers (worst scene decides)."""
    by = {(r["scene"], r["method"]): r for r in rows}
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    static = [s for s in scenes if SCENES[s][1] == "none"]
    ego = [s for s in scenes if SCENES[s][1] != "none"]

    def exact_vs_ref(s: str) -> float:
        c = checks.get(s, {})
        if "full_image_max_abs_diff_dn" in c:  # quick: small full frame + sampled lines at full size
            return max(c["full_image_max_abs_diff_dn"], c.get("sampled_lines_max_abs_diff_dn", 0.0))
        return by[(s, "exact")]["max_abs_err_dn"]

    specs = [
        ("exact_static_x_memcpy", "exact RS, static camera, in cache-warm frame copies", static, "<=",
         STATIC_X_MEMCPY, "x", lambda s: by[(s, "exact")]["x_memcpy"]),
        ("exact_static_x_memcpy_cold", "exact RS, static camera, in cache-cold frame copies", static, "<=",
         STATIC_X_MEMCPY, "x", lambda s: by[(s, "exact")]["x_memcpy_cold"]),
        ("exact_static_half_period", "exact RS, static camera, <= half the frame period", static, "<=",
         frame_period_ms / 2, "ms", lambda s: by[(s, "exact")]["ms_per_frame"]),
        ("exact_vs_reference_max_abs_diff", "exact RS equals the brute-force reference", scenes, "<=", 1.0, "DN",
         exact_vs_ref),
        ("exact_speedup_vs_reference", "exact RS faster than the brute-force reference", scenes, ">=", 300.0, "x",
         lambda s: by[(s, "exact")]["speedup_vs_reference"]),
        ("rs_gs_time_ratio", "exact RS frame time / GS frame time, static camera", static, "<=", 1.5, "x",
         lambda s: round(by[(s, "exact")]["ms_per_frame"] / by[(s, "gs")]["ms_per_frame"], 3)),
        ("exact_ego_frame_period", "exact RS with ego-motion within one frame period", ego, "<=",
         frame_period_ms, "ms", lambda s: by[(s, "exact")]["ms_per_frame"]),
        # The same speed targets on CPU time (frame: process CPU; copy: thread CPU), which a loaded machine's
        # scheduler does not inflate: the work the renderer does, as a quiet machine would show it.
        ("exact_static_x_memcpy_cpu", "exact RS, static camera, in cache-warm frame copies (CPU time)", static,
         "<=", STATIC_X_MEMCPY, "x", lambda s: by[(s, "exact")]["x_memcpy_cpu"]),
        ("exact_static_x_memcpy_cold_cpu", "exact RS, static camera, in cache-cold frame copies (CPU time)",
         static, "<=", STATIC_X_MEMCPY, "x", lambda s: by[(s, "exact")]["x_memcpy_cold_cpu"]),
        ("rs_gs_time_ratio_cpu", "exact RS frame CPU time / GS frame CPU time, static camera", static, "<=", 1.5,
         "x", lambda s: round(by[(s, "exact")]["cpu_ms_per_frame"] / by[(s, "gs")]["cpu_ms_per_frame"], 3)),
        ("exact_ego_frame_period_cpu", "exact RS with ego-motion within one frame period of CPU time", ego, "<=",
         frame_period_ms, "ms", lambda s: by[(s, "exact")]["cpu_ms_per_frame"]),
    ]
    out: dict[str, dict[str, Any]] = {}
    for name, desc, where, op, limit, unit, value_of in specs:
        per_scene = {s: value_of(s) for s in where}
        worst = None
        if per_scene:
            worst = max(per_scene.values()) if op == "<=" else min(per_scene.values())
        ok = None if worst is None else (worst <= limit if op == "<=" else worst >= limit)
        out[name] = {"description": desc, "op": op, "limit": round(limit, 4), "unit": unit, "value": worst,
                     "pass": ok, "per_scene": per_scene}
    return out


# -------------------------------------------------------------------------------------- whole run
def _machine() -> dict[str, Any]:
    import cv2
    import numba

    return {"platform": platform.platform(), "cpu": platform.processor() or platform.machine(),
            "cpu_count": os.cpu_count(), "loadavg": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
            "python": platform.python_version(), "numpy": np.__version__, "numba": numba.__version__,
            "numba_threads": numba.config.NUMBA_NUM_THREADS, "opencv": cv2.__version__}


def run_bench(width: int = 1920, height: int = 1080, quick: bool = False, out_dir: str | Path | None = None,
              progress: Callable[[str], None] | None = None, **overrides: Any) -> dict[str, Any]:
    """Run the bench and return its JSON document; with ``out_dir`` also write bench.json and bench.png."""
    cfg = make_config(quick, width, height, **overrides)
    say = progress or (lambda _msg: None)
    machine = _machine()
    floor = memcpy_floor(cfg.height, cfg.width, cfg.memcpy_repeats)
    say(f"floor: frame copy {floor['ms']:.3f} ms")
    timing = load_sensor(SENSOR).timing()
    rows: list[dict[str, Any]] = []
    checks: dict[str, dict[str, Any]] = {}
    skipped: list[dict[str, str]] = []
    for scene in cfg.scenes:
        bench = SceneBench(cfg, scene, say)
        bench.run()
        if not cfg.full_reference:
            say(f"{scene}: exact == reference check on the full {cfg.check_size[0]}x{cfg.check_size[1]} frame")
            bench.checks["full_image_max_abs_diff_dn"] = bench.full_image_check()
        rows += bench.rows(floor)
        checks[scene] = bench.checks
        skipped += bench.skipped
        del bench  # drops the scene's footage (6.7 GB at the line rate) before the next one
    scaling = scaling_table(cfg.scaling_sizes, cfg.scaling_walkers, cfg.scaling_frames, say) if (
        cfg.scaling_sizes and cfg.scaling_walkers) else None
    frame_period_ms = timing.frame_period_ns / 1e6
    doc = {
        "rows": rows,
        "floor": floor,
        "scaling": scaling,
        "targets": evaluate_targets(rows, checks, frame_period_ms),
        "machine": machine,
        "config": dataclasses.asdict(cfg),
        "sensor": {"name": SENSOR, "line_time_ns": timing.line_time_ns, "frame_period_ms": frame_period_ms},
        "baseline": ("reference image (one full render per line), full frame" if cfg.full_reference else
                     "exact per-line image; exact == reference checked on the full frame at "
                     f"{cfg.check_size[0]}x{cfg.check_size[1]} and on the reference's sampled lines"),
        "checks": checks,
        "skipped": skipped,
        "notes": _notes(cfg),
    }
    if out_dir is not None:
        from rollcam.common.files import write_atomic

        from .render_report import plot

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        doc["files"] = [str(out / "bench.json"), str(out / "bench.png")]
        write_atomic(out / "bench.json", (json.dumps(doc, indent=1) + "\n").encode())
        plot(rows, out / "bench.png", floor["ms"])
    return doc


def _notes(cfg: BenchConfig) -> list[str]:
    notes = [f"flow composes with flow_preset={cfg.flow_preset!r}, flow_margin_px={cfg.flow_margin_px} "
             "(full-frame DIS at 1080p costs seconds per frame)",
             "timings are medians after a warm-up; on a cold numba cache the first scene's warm-up compiles "
             "for about 100 s of CPU time (not timed)"]
    if LINE_RATE not in cfg.footage_fps:
        notes.append("line-rate footage (32,400 fps at 1080 lines) skipped: rendering it costs a full reference")
    return notes
