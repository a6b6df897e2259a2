"""The ``rollcam bench render`` document as a plot (error against time per method) and a plain-text table."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from rollcam.common.files import write_figure

_ZERO_ERR_PLOT = 1e-3  # where zero error sits on the plot's log axis when no error is above zero


def plot(rows: list[dict[str, Any]], path: Path, floor_ms: float) -> None:
    """Mean abs error (log) against ms per frame (log), one panel per scene, one labelled marker per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    fig, axes = plt.subplots(1, len(scenes), figsize=(6.5 * len(scenes), 5.5), squeeze=False)
    marks = {"reference": "s", "render": "o", "compose": "^"}
    for ax, scene in zip(axes[0], scenes, strict=True):
        mine = [r for r in rows if r["scene"] == scene]
        nonzero = [r["mean_abs_err_dn"] for r in mine if r["mean_abs_err_dn"] > 0]
        # Zero error sits a decade below the smallest nonzero one (log axis).
        zero = 10 ** (np.floor(np.log10(min(nonzero))) - 1) if nonzero else _ZERO_ERR_PLOT
        for r in mine:
            y = max(r["mean_abs_err_dn"], zero)
            ax.scatter(r["ms_per_frame"], y, marker=marks.get(r["kind"], "o"))
            label = r["method"] + (" (0)" if r["mean_abs_err_dn"] == 0 else "")
            ax.annotate(label, (r["ms_per_frame"], y), fontsize=7, xytext=(3, 3), textcoords="offset points")
        ax.axvline(floor_ms, color="grey", lw=0.8, ls="--")
        ax.set(xscale="log", yscale="log", title=scene, xlabel="ms per frame (dashed: one frame copy)",
               ylabel=f"mean abs error, DN (0 drawn at {zero:g})")
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    write_figure(Path(path), fig, dpi=110)


def format_table(doc: dict[str, Any]) -> str:
    """The rows, the floor and the targets as plain text."""
    head = f"{'scene':<11}{'method':<24}{'ms/frame':>11}{'cpu_ms':>9}{'x_memcpy':>10}{'x_cold':>8}{'vs_ref':>9}" \
           f"{'mean_err':>10}{'max_err':>8}{'box_px':>8}  note"
    lines = [head, "-" * len(head)]
    for r in doc["rows"]:
        box = "-" if r["max_box_err_px"] is None else f"{r['max_box_err_px']:.2f}"
        cpu = "-" if r.get("cpu_ms_per_frame") is None else f"{r['cpu_ms_per_frame']:.2f}"
        lines.append(f"{r['scene']:<11}{r['method']:<24}{r['ms_per_frame']:>11.2f}{cpu:>9}{r['x_memcpy']:>10.1f}"
                     f"{r['x_memcpy_cold']:>8.1f}{r['speedup_vs_reference']:>9.1f}{r['mean_abs_err_dn']:>10.4f}{r['max_abs_err_dn']:>8.0f}"
                     f"{box:>8}  {r['note']}")
    f = doc["floor"]
    lines += ["", f"floor: {f['what']}: {f['ms']:.3f} ms ({f['gb_per_s']:.1f} GB/s; cache-cold {f['cold_ms']:.3f} ms; "
              f"CPU {f.get('cpu_ms', float('nan')):.3f} / cold {f.get('cold_cpu_ms', float('nan')):.3f} ms)",
              f"baseline: {doc['baseline']}", ""]
    if doc.get("scaling"):
        from .render_scaling import format_scaling

        lines += [*format_scaling(doc["scaling"]), ""]
    lines.append("targets:")
    for name, t in doc["targets"].items():
        verdict = {True: "PASS", False: "FAIL", None: "n/a"}[t["pass"]]
        lines.append(f"  {verdict:<5}{name}: {t['value']} {t['op']} {t['limit']} {t['unit']}  {t['per_scene']}")
    for s in doc["skipped"]:
        lines.append(f"skipped: {s['scene']} {s['method']}: {s['why']}")
    lines += [f"note: {n}" for n in doc["notes"]]
    return "\n".join(lines)
