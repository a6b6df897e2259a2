"""``rollcam list``: the emulated sensors, then each device backend's cameras (or why there are none)."""

from __future__ import annotations

import argparse
import json
from typing import Any

from . import Subparsers


def add_parser(sub: Subparsers) -> argparse.ArgumentParser:
    """Add ``rollcam list``."""
    p = sub.add_parser("list", help="list the emulated sensors and attached cameras",
                       description="List the emulated sensors (shutter, default mode, frame rate, line time), then "
                                   "V4L2, OAK and USB video devices; an empty section says why (backend missing, "
                                   "nothing plugged in).")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    return p


def sensor_rows() -> list[dict[str, Any]]:
    """One row per emulated sensor: name, shutter, default mode, fps, line time, readout, description."""
    from rollcam.sim.hwconfig import list_sensors, load_sensor

    rows = []
    for name in list_sensors():
        s = load_sensor(name)
        mode, timing = s.mode(), s.timing()
        rows.append({"name": s.name, "uri": f"emu:{s.name}", "shutter": s.shutter, "default_mode": mode.name,
                     "width": mode.width, "height": mode.height, "fps": round(timing.fps, 3),
                     "line_time_ns": timing.line_time_ns, "readout": s.readout.value,
                     "modes": [m.name for m in s.modes], "description": s.description})
    return rows


def run(args: argparse.Namespace) -> int:
    """Print the sensors and the device sections as a table or one JSON document."""
    from ..sources.discover import SECTIONS, discover

    rows = sensor_rows()
    devices = discover()
    if args.json:
        print(json.dumps({"emulated": rows, **devices}))
        return 0
    print("Emulated sensors (open as emu:NAME):")
    header = ("NAME", "SHUTTER", "DEFAULT MODE", "FPS", "LINE TIME", "READOUT")
    table = [header] + [(r["name"], r["shutter"], r["default_mode"], f"{r['fps']:.2f}",
                         f"{r['line_time_ns']} ns", r["readout"]) for r in rows]
    widths = [max(len(row[i]) for row in table) for i in range(len(header))]
    for row in table:
        print("  " + "  ".join(c.ljust(w) if i in (0, 1, 2, 5) else c.rjust(w)
                               for i, (c, w) in enumerate(zip(row, widths, strict=True))).rstrip())
    for key, (heading, _) in SECTIONS.items():
        section = devices[key]
        print(f"\n{heading}:")
        for d in section["devices"]:
            extra = "  ".join(f"{k}={v}" for k, v in d.items() if k != "uri" and v not in ("", None))
            print(f"  {d['uri']}  {extra}".rstrip())
        if not section["devices"]:
            print(f"  none: {section['note']}")
    return 0
