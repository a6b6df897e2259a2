"""Evaluation results laid out as the study's tables (one row per speed and shutter, GS->RS difference) and
as a bar chart."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rollcam.common.files import write_figure

METRICS = ("P", "R", "mAP50", "mAP50_95")
HEADERS = ("P", "R", "mAP@0.5", "mAP@0.5:0.95")
STUDY_ROW_NAMES = {"normal": "Normal", "fast": "Faster"}
PIPELINES = ("gs", "rs", "rs_gsbox", "rs_gyro")
"""Row order within a speed: the study's GS and RS, then (``--correct gyro``) the RS images against the GS
labels and the gyro-corrected RS images against the GS labels (``corrected.py``)."""


def row_name(speed: str | None, shutter: str | None, fallback: str) -> str:
    """``Normal_GS``, ``Faster_RS`` (the study's names), or the set's own name."""
    if speed is None or shutter is None:
        return fallback
    return f"{STUDY_ROW_NAMES.get(speed, speed)}_{shutter.upper()}"


def build_document(rows: list[dict[str, Any]], meta: dict[str, Any]) -> dict[str, Any]:
    """The ``--json`` document: ``results[speed][shutter]`` = {P, R, mAP50, mAP50_95, ...} and
    ``results[speed]['gs_to_rs']`` = RS minus GS for each metric (and ``gs_to_rs_gsbox``, ``gs_to_rs_gyro`` for
    the corrected pipeline's rows); sets without speed/shutter under ``sets``."""
    results: dict[str, dict[str, Any]] = {}
    sets: dict[str, Any] = {}
    for r in rows:
        m = {k: round(r["metrics"][k], 6) for k in METRICS} | {
            k: r["metrics"][k] for k in ("images", "boxes", "detections")} | {"conf": round(r["metrics"]["conf"], 4)}
        if r["speed"] is None:
            sets[r["name"]] = m
        else:
            results.setdefault(r["speed"], {})[r["shutter"]] = m
    for per in results.values():
        for p in PIPELINES[1:]:
            if "gs" in per and p in per:
                per[f"gs_to_{p}"] = {k: round(per[p][k] - per["gs"][k], 6) for k in METRICS}
    return {**meta, "results": results, "sets": sets}


def format_table(doc: dict[str, Any]) -> str:
    """The study's table layout: Validation | P | R | mAP@0.5 | mAP@0.5:0.95, with a GS->RS row per speed."""
    names = [row_name(sp, sh, sp) for sp, per in doc["results"].items() for sh in PIPELINES if sh in per]
    c = max([14, *(len(n) + 1 for n in [*names, *doc["sets"]])])
    head = f"{'Validation':<{c}}" + "".join(f"{h:>14}" for h in HEADERS)
    lines = [f"detector {doc['detector']}, split {doc['split']}", head, "-" * len(head)]
    for speed, per in doc["results"].items():
        lines.extend(f"{row_name(speed, sh, speed):<{c}}" + "".join(f"{per[sh][k]:>14.3f}" for k in METRICS)
                     + f"   ({per[sh]['images']} images, {per[sh]['boxes']} boxes)" for sh in PIPELINES if sh in per)
        for p in PIPELINES[1:]:
            if f"gs_to_{p}" in per:
                label = "  GS->" + p.upper()
                lines.append(f"{label:<{c}}" + "".join(f"{per[f'gs_to_{p}'][k]:>+14.3f}" for k in METRICS))
    for name, m in doc["sets"].items():
        lines.append(f"{name:<{c}}" + "".join(f"{m[k]:>14.3f}" for k in METRICS)
                     + f"   ({m['images']} images, {m['boxes']} boxes)")
    return "\n".join(lines)


def plot(doc: dict[str, Any], path: Path) -> None:
    """Grouped bars: one group per metric, one bar per row (speed x shutter); written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    rows = [(row_name(sp, sh, sp), per[sh]) for sp, per in doc["results"].items() for sh in PIPELINES if sh in per]
    rows += list(doc["sets"].items())
    fig, ax = plt.subplots(figsize=(8, 4.5))
    x = np.arange(len(METRICS))
    width = 0.8 / max(len(rows), 1)
    for i, (name, m) in enumerate(rows):
        bars = ax.bar(x + (i - (len(rows) - 1) / 2) * width, [m[k] for k in METRICS], width, label=name)
        ax.bar_label(bars, fmt="%.2f", fontsize=7)
    ax.set_xticks(x, HEADERS)
    ax.set_ylim(0, 1.05)
    ax.set_title(f"{doc['detector']} on the {doc['split']} split")
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    write_figure(Path(path), fig, dpi=110)
