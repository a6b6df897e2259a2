"""The emulated device's frame times as users stream it: ``rollcam bench device`` (issue 42).

Every row is timed through the public API, ``open_camera(uri).read()`` (median of ``frames`` reads after
``warmup`` reads, wall and process CPU ms), on the issue's scene: a 1920x1080 street with 20 walkers, IMX219.
The targets, judged from the same run:

- ``static_yuyv`` / ``static_raw10``: YUYV and CSI-2 RAW10 (pRAA) with the sensor model and the default blur
  bound, static camera: <= one 30 fps frame period (33.3 ms) wall.
- ``ego_walk`` ... ``ego_vehicle``: each ego preset, YUYV with the sensor model on: <= 33.3 ms wall (CPU beside).
- ``static_rs_x_copy``: the static exact RS frame (BGR3, the clean path) <= 8x one warm frame copy of the same
  size, measured in the same process (``rollcam.benchmarks.bench.memcpy_floor``).
- ``sensor_stages_vs_clean``: what the sensor model adds with blur off (YUYV ``blur_px=0`` read minus the clean
  BGR3 read) <= 25 % of the clean read.
- ``night_lights_x_steady``: a night street with its modulated lamps and signs on against the same street with
  them off (BGR3): <= 1.5x.

Each missed target names its measured cause: the functions that took most of one profiled read of that row
(``cProfile``, own time), so a report says where the time went, not only that it was too much.
"""

from __future__ import annotations

import cProfile
import os
import pstats
import time
from typing import Any

import numpy as np
from rollcam.host import open_camera

from .bench import memcpy_floor

EGO_PRESETS = ("walk", "pan", "drone", "vehicle")
FRAME_PERIOD_MS = 1000.0 / 30.0
STATIC_X_COPY = 8.0
SENSOR_STAGES_FRACTION = 0.25
NIGHT_LIGHTS_X = 1.5


def row_uris(size: tuple[int, int]) -> dict[str, str]:
    """Row name -> source URI of every row (the issue's scene at ``size``)."""
    base = f"emu:imx219?size={size[0]}x{size[1]}&scene=street"
    night = f"{base}&time=night"
    rows = {"static_bgr3": base, "static_yuyv": f"{base}&format=YUYV", "static_raw10": f"{base}&format=pRAA",
            "static_yuyv_noblur": f"{base}&format=YUYV&blur_px=0"}
    rows.update({f"ego_{e}": f"{base}&format=YUYV&ego={e}" for e in EGO_PRESETS})
    rows.update({"night_steady": f"{night}&lamps=off", "night_lights": f"{night}&lamps=on"})
    return rows


def time_reads(uri: str, frames: int, warmup: int) -> dict[str, Any]:
    """Median wall and process-CPU ms of ``read()`` on a fresh ``open_camera(uri)``, after ``warmup`` reads."""
    wall, cpu = [], []
    with open_camera(uri) as cam:
        for _ in range(warmup):
            cam.read()
        for _ in range(frames):
            c0, t0 = time.process_time(), time.perf_counter()
            cam.read()
            wall.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
    return {"uri": uri, "frames": frames, "wall_ms": round(1e3 * float(np.median(wall)), 2),
            "cpu_ms": round(1e3 * float(np.median(cpu)), 2)}


def profile_read(uri: str, top: int = 3) -> list[dict[str, Any]]:
    """The ``top`` functions by own time in one profiled ``read()`` (after one warm read): a miss's cause."""
    with open_camera(uri) as cam:
        cam.read()
        prof = cProfile.Profile()
        prof.enable()
        cam.read()
        prof.disable()
    stats = pstats.Stats(prof).stats  # type: ignore[attr-defined]
    total = sum(v[2] for v in stats.values()) or 1.0
    rows = sorted(stats.items(), key=lambda kv: kv[1][2], reverse=True)[:top]
    return [{"function": f"{os.path.basename(f)}:{line}({name})", "calls": v[1], "ms": round(1e3 * v[2], 1),
             "share": round(v[2] / total, 3)} for (f, line, name), v in rows]


def _target(value: float, op: str, limit: float, rows: tuple[str, ...]) -> dict[str, Any]:
    ok = value <= limit if op == "<=" else value >= limit
    return {"value": round(value, 3), "op": op, "limit": round(limit, 3), "pass": bool(ok), "rows": list(rows)}


def evaluate(rows: dict[str, dict[str, Any]], floor: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """The issue's targets from this run's rows (every row present is judged)."""
    out: dict[str, dict[str, Any]] = {}
    for name in ("static_yuyv", "static_raw10", *(f"ego_{e}" for e in EGO_PRESETS)):
        if name in rows:
            out[f"{name}_frame_period"] = _target(rows[name]["wall_ms"], "<=", FRAME_PERIOD_MS, (name,))
    if "static_bgr3" in rows:
        out["static_rs_x_copy"] = _target(rows["static_bgr3"]["wall_ms"] / floor["ms"], "<=", STATIC_X_COPY,
                                          ("static_bgr3",))
        if "static_yuyv_noblur" in rows:
            clean = rows["static_bgr3"]["wall_ms"]
            out["sensor_stages_vs_clean"] = _target((rows["static_yuyv_noblur"]["wall_ms"] - clean) / clean, "<=",
                                                    SENSOR_STAGES_FRACTION, ("static_yuyv_noblur", "static_bgr3"))
    if "night_lights" in rows and "night_steady" in rows:
        out["night_lights_x_steady"] = _target(rows["night_lights"]["wall_ms"] / rows["night_steady"]["wall_ms"],
                                               "<=", NIGHT_LIGHTS_X, ("night_lights", "night_steady"))
    return out


def run_device_bench(size: tuple[int, int] = (1920, 1080), *, frames: int = 8, warmup: int = 2,
                     only: tuple[str, ...] | None = None, causes: bool = True, say: Any = print) -> dict[str, Any]:
    """Time every row (or the ``only`` ones), judge the targets, and profile one read of each missed row."""
    uris = row_uris(size)
    names = [n for n in uris if only is None or n in only]
    floor = memcpy_floor(size[1], size[0])
    rows: dict[str, dict[str, Any]] = {}
    for i, name in enumerate(names):
        say(f"{name} ({i + 1}/{len(names)})")
        rows[name] = time_reads(uris[name], frames, warmup)
    targets = evaluate(rows, floor)
    if causes:
        for t in targets.values():
            if not t["pass"]:
                t["cause"] = {r: profile_read(uris[r]) for r in t["rows"]}
    return {"size": f"{size[0]}x{size[1]}", "frames": frames, "warmup": warmup, "load_average": os.getloadavg(),
            "cpus": os.cpu_count(), "floor": floor, "rows": rows, "targets": targets}


def format_report(doc: dict[str, Any]) -> str:
    """The rows and targets ``rollcam bench device`` prints, each miss with its profiled cause."""
    load = ", ".join(f"{x:.1f}" for x in doc["load_average"])
    lines = [f"device {doc['size']} street, 20 walkers, median of {doc['frames']} reads after {doc['warmup']} "
             f"(load average {load}; warm frame copy {doc['floor']['ms']:.3f} ms)"]
    lines += [f"  {name:20s} {r['wall_ms']:10.1f} ms wall {r['cpu_ms']:10.1f} ms CPU  {r['uri']}"
              for name, r in doc["rows"].items()]
    for name, t in doc["targets"].items():
        lines.append(f"  {'PASS' if t['pass'] else 'FAIL'} {name}: {t['value']} {t['op']} {t['limit']}")
        for row, top in t.get("cause", {}).items():
            lines.append(f"       cause ({row}): " + "; ".join(f"{c['function']} {c['ms']} ms x{c['calls']} "
                                                               f"({c['share']:.0%})" for c in top))
    return "\n".join(lines)
