"""The study's report from its runs' test results: tables beside the study's numbers, statistics, charts.

Every cell is the mean and sample standard deviation over the training seeds. A GS->RS difference is RS minus
GS (absolute, and relative to GS); it counts as *larger than the seed-to-seed spread* when its magnitude
exceeds twice its standard error, ``sqrt(s_gs^2 / n_gs + s_rs^2 / n_rs)`` (about a 95 % Welch test for
normal seeds; with 3 seeds a rough one, said in the report). Every seed is tested on the same images, so the
seed spread leaves out what the choice of test images adds; for mAP@0.5:0.95, whose per-run bootstrap standard
error ``b`` each run measures, a difference also carries ``se_images = sqrt(se^2 + b_gs^2 + b_rs^2)`` (the GS and
RS images taken as independent, which overstates it for paired instants) and its 95 % interval
``delta +- 2 se_images`` (about 95 %; with 3-5 seeds the seed term's few degrees of freedom make it rough):
what the difference would be on all the streets the generator makes. Files:
``report.json``, ``report.md``, ``report.png``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from rollcam.common.files import write_atomic, write_figure

from .labels import STUDY_BOX_AREA_PX2
from .study_settings import LABEL_ARMS, SHUTTERS, StudySettings, subset

METRICS = ("P", "R", "mAP50", "mAP50_95")
STUDY_REFERENCE = {
    "table1": "YOLOv8 fine-tuned per subset: mAP@0.5 within 2 % between shutters; mAP@0.5:0.95 lower under RS "
              "by up to 24 %",
    "table3_mAP50": {"train RS / test RS": 0.82, "train GS / test RS": 0.63, "train RS / test GS+RS": 0.80},
    "table1_yolov8": {"Normal_GS": [0.97, 0.70, 0.82, 0.60], "Normal_RS": [0.94, 0.67, 0.82, 0.44],
                      "Faster_GS": [0.99, 0.97, 0.98, 0.72], "Faster_RS": [0.98, 0.97, 0.99, 0.59]},
    "table2_coco_yolov8": {"Normal_GS": [0.35, 0.21, 0.12, 0.02], "Normal_RS": [0.91, 0.55, 0.67, 0.31],
                           "Faster_GS": [0.23, 0.16, 0.05, 0.0], "Faster_RS": [0.13, 0.10, 0.05, 0.0]},
}
"""What the study reports (as its issue summarises it), printed beside rollcam's numbers."""
SPEED_X = {"normal": 1.0, "fast": 10.0}


def _stats(values: list[float]) -> dict[str, Any]:
    n = len(values)
    mean = sum(values) / n if n else float("nan")
    std = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1)) if n > 1 else 0.0
    return {"mean": round(mean, 6), "std": round(std, 6), "n": n, "values": [round(v, 6) for v in values]}


def difference(gs: dict[str, Any], rs: dict[str, Any], b_gs: dict[str, Any] | None = None,
               b_rs: dict[str, Any] | None = None) -> dict[str, Any]:
    """RS minus GS of two seed groups: absolute, relative to GS, its standard error and whether it exceeds
    twice that (``beyond_spread``). With the groups' test-image standard errors ``b_gs`` and ``b_rs`` (cells of
    ``mAP50_95_se``), also ``se_images``, the standard error with the test images' sampling added, its
    ``beyond_images`` and ``interval``, the relative 95 % interval ``delta +- 2 se_images`` over GS."""
    delta = rs["mean"] - gs["mean"]
    se = math.sqrt(gs["std"] ** 2 / max(gs["n"], 1) + rs["std"] ** 2 / max(rs["n"], 1))
    rel = delta / gs["mean"] if gs["mean"] else float("nan")
    if min(gs["n"], rs["n"]) < 2:  # one seed has no spread to compare with
        beyond = False
    else:
        beyond = bool(abs(delta) > 2 * se) if se > 0 else bool(delta != 0)
    out = {"delta": round(delta, 6), "relative": round(rel, 6) if math.isfinite(rel) else None,
           "se": round(se, 6), "beyond_spread": beyond, "seeds": min(gs["n"], rs["n"])}
    if b_gs and b_rs and b_gs["n"] and b_rs["n"] and min(gs["n"], rs["n"]) >= 2:
        full = math.sqrt(se ** 2 + b_gs["mean"] ** 2 + b_rs["mean"] ** 2)
        out |= {"se_images": round(full, 6), "beyond_images": bool(abs(delta) > 2 * full)}
        if gs["mean"]:
            out["interval"] = [round((delta - 2 * full) / gs["mean"], 6), round((delta + 2 * full) / gs["mean"], 6)]
    return out


def differences(gs: dict[str, Any], rs: dict[str, Any]) -> dict[str, Any]:
    """``difference`` of every metric of two cells; mAP@0.5:0.95 with their test-image errors (``mAP50_95_se``)."""
    return {m: difference(gs[m], rs[m], *((gs["mAP50_95_se"], rs["mAP50_95_se"]) if m == "mAP50_95" else ()))
            for m in METRICS}


def _cell(results: list[dict[str, Any]], group: str, train: tuple[str, ...], test: str,
          metric: str, **match: Any) -> dict[str, Any]:
    vals = [r["test"][test][metric] for r in results if r["job"]["group"] in group.split("|")
            and tuple(r["job"]["train"]) == train and all(r["job"].get(k) == v for k, v in match.items())
            and metric in r["test"].get(test, {})]
    return _stats(vals)


def label_arm(s: StudySettings, results: list[dict[str, Any]]) -> dict[str, Any]:
    """Per speed of the label arm: the GS models (``gs_model``) and the RS models of each arm (tested on their own
    labels, and the other arms on exact labels too), with each arm's GS->RS difference."""
    out = {}
    for sp in s.label_speeds:
        gs, rs = (subset(sp, "gs"),), (subset(sp, "rs"),)
        row: dict[str, Any] = {"gs_model": {m: _cell(results, "t1|speed", gs, "gs", m, scenes=None, cameras=None)
                                            for m in (*METRICS, "mAP50_95_se")}}
        for arm in LABEL_ARMS:
            group = "t1|speed" if arm == "exact" else "labels"
            match = {"scenes": None, "cameras": None} if arm == "exact" else {"labels": arm}
            cell = {m: _cell(results, group, rs, "rs", m, **match) for m in METRICS}
            cell["se_test"] = _cell(results, group, rs, "rs", "mAP50_95_se", **match)
            if arm != "exact":
                cell["on_exact"] = {m: _cell(results, group, rs, "rs_exact", m, **match) for m in METRICS}
            cell["gs_to_rs"] = differences(row["gs_model"], cell | {"mAP50_95_se": cell["se_test"]})
            row[arm] = cell
        out[sp] = row
    return out


def aggregate(s: StudySettings, results: list[dict[str, Any]]) -> dict[str, Any]:
    """The report's numbers: Table 1, Table 3, the RS penalty per speed (RGB and raw), Fig. 4."""
    def shutter_pair(group: str, speed: str, **match: Any) -> dict[str, Any]:
        row = {}
        for sh in SHUTTERS:
            row[sh] = {m: _cell(results, group, (subset(speed, sh),), sh, m, **match)
                       for m in (*METRICS, "mAP50_95_se")}
        row["gs_to_rs"] = differences(row["gs"], row["rs"])
        return row

    table1 = {sp: shutter_pair("t1", sp, scenes=None, cameras=None) for sp in s.speeds if sp in SPEED_X}
    speed = {sp: shutter_pair("t1" if sp in SPEED_X else "speed", sp, scenes=None, cameras=None) for sp in s.speeds}
    raw = {sp: shutter_pair("raw", sp) for sp in s.raw_speeds}
    table3 = {}
    for sp in sorted(set(s.t3_speeds) | set(table1), key=list(s.speeds).index):
        rows = {}
        for label, group, train in (("GS", "t1", (subset(sp, "gs"),)), ("RS", "t1", (subset(sp, "rs"),)),
                                    ("GS+RS", "t3", (subset(sp, "gs"), subset(sp, "rs")))):
            if group == "t3" and sp not in s.t3_speeds:
                continue
            rows[label] = {test: {m: _cell(results, group, train, test, m, scenes=None, cameras=None)
                                  for m in ("mAP50", "mAP50_95")} for test in ("gs", "rs", "gsrs")}
        table3[sp] = rows
    f4 = [r for r in results if r["job"]["group"] == "fig4"]
    sh = s.fig4_subset.rsplit("_", 1)[1]
    full = [r for r in results if r["job"]["group"] == "t1" and tuple(r["job"]["train"]) == (s.fig4_subset,)
            and r["job"]["seed"] == s.seeds[0]]
    fig4: dict[str, list[dict[str, Any]]] = {"scenes": [], "cameras": []}
    for r in f4 + full:
        point = {k: r["test"][sh][k] for k in ("mAP50", "mAP50_95")}
        if r["job"]["cameras"] is None:
            fig4["scenes"].append({"n": r["job"]["scenes"] or n_train_scenes(s), **point})
        if r["job"]["scenes"] is None:
            fig4["cameras"].append({"n": r["job"]["cameras"] or s.cameras, **point})
    for k in fig4:
        fig4[k].sort(key=lambda p: p["n"])
    base = next((r["test"] for r in results if r["job"]["group"] == "base"), None)
    return {"table1": table1, "table3": table3, "speed": speed, "raw": raw, "fig4": fig4,
            "label_arm": label_arm(s, results), "base": base}


def n_train_scenes(s: StudySettings) -> int:
    """Training scenes of the study's dataset (its split of scenes)."""
    from ..datasets.plan import split_of_scenes

    return split_of_scenes(s.scenes, s.split).count("train")


def _ms(c: dict[str, Any]) -> str:
    return f"{c['mean']:.3f} ± {c['std']:.3f}"


def _diff(d: dict[str, Any]) -> str:
    rel = f" ({d['relative']:+.1%})" if d["relative"] is not None else ""
    return f"{d['delta']:+.3f}{rel}{' *' if d['beyond_spread'] else ''}"


def _speed_label(sp: str) -> str:
    return f"{SPEED_X.get(sp) or float(sp):g}x ({sp})"


def _spread(d: dict[str, Any], what: str = "the spread") -> str:
    """Whether a difference is beyond or within the seed spread, or that one seed has none yet."""
    if d.get("seeds", 2) < 2:
        return "one seed so far: no spread to judge by"
    return f"{'beyond' if d['beyond_spread'] else 'within'} {what}"


def _interval(d: dict[str, Any]) -> str:
    """``; 95 % interval ...`` of a difference that carries the test images' sampling, else nothing."""
    if "interval" not in d:
        return ""
    lo, hi = d["interval"]
    return f"; with the test images' sampling, about 95 % interval {lo:+.1%} to {hi:+.1%}"


def statements(agg: dict[str, Any]) -> list[str]:
    """The plain answers: per speed, is mAP@0.5 within 2 % between shutters, how far mAP@0.5:0.95 moves."""
    out = []
    for name, table in (("RGB", agg["speed"]), ("raw mosaic", agg["raw"])):
        for sp, row in table.items():
            d50, d95 = row["gs_to_rs"]["mAP50"], row["gs_to_rs"]["mAP50_95"]
            if not row["gs"]["mAP50"]["n"] or not row["rs"]["mAP50"]["n"]:
                continue  # not run (rollcam study --only)
            if d50["relative"] is None or d95["relative"] is None:
                out.append(f"{name}, walkers at {_speed_label(sp)}: not measurable (the GS models find nothing: "
                           "mAP 0; train longer)")
                continue
            within = abs(d50["relative"]) <= 0.02
            out.append(f"{name}, walkers at {_speed_label(sp)}: mAP@0.5 {row['gs']['mAP50']['mean']:.3f} (GS) vs "
                       f"{row['rs']['mAP50']['mean']:.3f} (RS), {d50['relative']:+.1%}: "
                       f"{'within' if within else 'NOT within'} 2 %; mAP@0.5:0.95 {d95['relative']:+.1%} "
                       f"({_spread(d95, 'the seed-to-seed spread')}{_interval(d95)}).")
    return out


ARM_NAMES = {"exact": "exact RS labels", "gs": "GS labels on RS images", "hand": "hand-like labels"}


def label_statements(agg: dict[str, Any]) -> list[str]:
    """Per label arm and speed: does it show the study's pattern (mAP@0.5 unchanged between shutters,
    mAP@0.5:0.95 lower under RS beyond the seed spread, and beyond the test images' sampling where the runs
    measured it)?"""
    out = []
    for sp, row in agg.get("label_arm", {}).items():
        for arm in LABEL_ARMS:
            cell = row[arm]
            if not cell["mAP50"]["n"] or not row["gs_model"]["mAP50"]["n"]:
                continue
            d50, d95 = cell["gs_to_rs"]["mAP50"], cell["gs_to_rs"]["mAP50_95"]
            if d50["relative"] is None or d95["relative"] is None:
                continue
            same50 = abs(d50["relative"]) <= 0.02 or not d50["beyond_spread"]
            drop95 = d95["delta"] < 0 and d95.get("beyond_images", d95["beyond_spread"])  # the test images too
            verdict = "shows the study's pattern" if same50 and drop95 else "does not show the study's pattern"
            if d95.get("seeds", 2) < 2:
                verdict = "one seed cannot say"
            out.append(f"walkers at {_speed_label(sp)}, {ARM_NAMES[arm]}: mAP@0.5 {d50['relative']:+.1%} "
                       f"({_spread(d50)}), mAP@0.5:0.95 {d95['relative']:+.1%} ({_spread(d95)}"
                       f"{_interval(d95)}): {verdict}.")
    return out


def _label_sections(s: StudySettings, agg: dict[str, Any], extra: dict[str, Any]) -> list[str]:
    lines: list[str] = []
    arm = agg.get("label_arm", {})
    if arm and any(row["gs_model"]["mAP50"]["n"] for row in arm.values()):
        lines += ["## The label arm: RS models trained and tested with exact, GS and hand-like labels", "",
                  "Every RS model is trained and tested with its arm's labels of the RS images (GS models: exact GS "
                  "labels, as the study's renderer gave). `GS->RS`: the arm's RS cell minus the GS cell; `*` beyond "
                  "twice the standard error over seeds. `test SE`: the mean over seeds of the bootstrap standard "
                  "error of mAP@0.5:0.95 over the test images (what a single run's number carries from the choice "
                  "of test images). `on exact`: the same models scored against the exact RS labels.", "",
                  "| speed | labels | mAP@0.5 | mAP@0.5:0.95 | test SE | GS->RS mAP@0.5 | GS->RS mAP@0.5:0.95 | "
                  "on exact mAP@0.5 / mAP@0.5:0.95 |", "|---|---|---:|---:|---:|---:|---:|---:|"]
        for sp, row in arm.items():
            g = row["gs_model"]
            if not g["mAP50"]["n"]:
                continue
            lines.append(f"| {_speed_label(sp)} | GS model, GS images | {_ms(g['mAP50'])} | {_ms(g['mAP50_95'])} | "
                         "| | | |")
            for a in LABEL_ARMS:
                c = row[a]
                if not c["mAP50"]["n"]:
                    continue
                on = c.get("on_exact")
                ex = f"{_ms(on['mAP50'])} / {_ms(on['mAP50_95'])}" if on else "(same)"
                lines.append(f"| {_speed_label(sp)} | {ARM_NAMES[a]} | {_ms(c['mAP50'])} | {_ms(c['mAP50_95'])} | "
                             f"{c['se_test']['mean']:.3f} | {_diff(c['gs_to_rs']['mAP50'])} | "
                             f"{_diff(c['gs_to_rs']['mAP50_95'])} | {ex} |")
        lines.append("")
    tables = extra.get("labels")
    ref = STUDY_BOX_AREA_PX2
    if tables:
        lines += ["## Labels alone: box sizes and the label ceiling", "",
                  "Mean labelled box area of the train split, in pixels and scaled to the study's 1920x1080 "
                  f"(the study: Normal RS {ref['normal_rs']:,.0f}, Normal GS {ref['normal_gs']:,.0f}, Faster RS "
                  f"{ref['fast_rs']:,.0f}, Faster GS {ref['fast_gs']:,.0f} px2; RS/GS "
                  f"{ref['normal_rs'] / ref['normal_gs']:.3f} normal, {ref['fast_rs'] / ref['fast_gs']:.3f} faster). "
                  "Label ceiling: the exact RS boxes scored as detections (score 1) against the arm's RS test "
                  "labels, the mAP a perfect detector of the true extents would get; `hand_inset`: the exact boxes "
                  "moved in by the annotator's inset, a detector that learnt the annotator's bias and is left "
                  "with the scatter of its hand.", "",
                  "| speed | boxes | GS px2 (at 1080p) | " + " | ".join(f"RS {ARM_NAMES[a]} px2 (at 1080p), RS/GS"
                                                                    for a in LABEL_ARMS)
                  + " | " + " | ".join(f"ceiling {a} mAP@0.5 / mAP@0.5:0.95" for a in (*LABEL_ARMS, "hand_inset"))
                  + " |", "|---|---:|---:|" + "---:|" * (2 * len(LABEL_ARMS) + 1)]
        for sp, b in tables["boxes"].items():
            g = b["gs_images"]
            cells = [f"{b[a]['mean_area_px2']:.0f} ({b[a]['mean_area_study_px2']:,.0f}), "
                     f"{b[a]['mean_area_px2'] / max(g['mean_area_px2'], 1e-9):.3f}" for a in LABEL_ARMS]
            ceil = [f"{tables['ceiling'][sp][a]['mAP50']:.3f} / {tables['ceiling'][sp][a]['mAP50_95']:.3f}"
                    for a in (*LABEL_ARMS, "hand_inset") if a in tables["ceiling"][sp]]
            lines.append(f"| {_speed_label(sp)} | {b['exact']['boxes']} | {g['mean_area_px2']:.0f} "
                         f"({g['mean_area_study_px2']:,.0f}) | " + " | ".join(cells + ceil) + " |")
        lines.append("")
    coco = extra.get("coco")
    if coco:
        ref = STUDY_REFERENCE["table2_coco_yolov8"]
        lines += ["## Table 2 analogue: COCO-trained detectors, not fine-tuned", "",
                  "P / R / mAP@0.5 / mAP@0.5:0.95 on the test splits (RS: exact labels; the last columns the RS "
                  "images against GS and hand-like labels, mAP@0.5 / mAP@0.5:0.95), beside the study's YOLOv8 "
                  "trained on COCO only (its RS test labels hand-drawn).", "",
                  "| detector | subset | P | R | mAP@0.5 | mAP@0.5:0.95 | RS on GS labels | RS on hand labels | "
                  "study YOLOv8 (P / R / mAP@0.5 / mAP@0.5:0.95) |", "|---|---|---:|---:|---:|---:|---:|---:|---|"]
        for doc in coco.values():
            for sp, cells in doc.items():
                if sp == "spec":
                    continue
                name = {"normal": "Normal", "fast": "Faster"}[sp]
                for sh in SHUTTERS:
                    c = cells[sh]
                    alt = ["", ""] if sh == "gs" else [
                        f"{cells[f'rs_{a}labels']['mAP50']:.3f} / {cells[f'rs_{a}labels']['mAP50_95']:.3f}"
                        for a in ("gs", "hand")]
                    study = " / ".join(f"{v:.2f}" for v in ref[f"{name}_{sh.upper()}"])
                    lines.append(f"| `{doc['spec']}` | {name}_{sh.upper()} | {c['P']:.3f} | {c['R']:.3f} | "
                                 f"{c['mAP50']:.3f} | {c['mAP50_95']:.3f} | {alt[0]} | {alt[1]} | {study} |")
        lines.append("")
    return lines


def _time_line(timing: dict[str, Any]) -> str:
    train = f"{timing['train_s_sum'] / 3600:.2f} h of training summed over runs"
    if not timing["workers"]:
        return f"Report of the finished runs ({timing.get('finished', 0)} of {timing.get('planned', 0)}; {train})."
    if timing.get("finished", 0) < timing.get("planned", 0):
        return (f"Partial: {timing['finished']} of {timing['planned']} runs finished ({train}); a cell's n says "
                "how many seeds it has.")
    return (f"Time: {timing['total_s'] / 60:.1f} min on {timing['workers']} worker(s) "
            f"({timing['datasets_s']:.0f} s of it rendering; {train}).")


def report_markdown(s: StudySettings, agg: dict[str, Any], timing: dict[str, Any], command: str,
                    extra: dict[str, Any] | None = None) -> str:
    """The report people read."""
    n = len(s.seeds)
    start = (f"fine-tuned for {s.epochs} epochs per run from one base model ({s.base_epochs} epochs on the GS "
             f"images of {s.base_frames} pairs of {s.base_scenes} other scenes, dataset seed {s.base_seed})"
             if s.base_frames else f"trained from scratch for {s.epochs} epochs per run")
    lines = [f"# rollcam study, `{s.name}` setting", "",
             f"Paired GS/RS datasets with exact labels ({s.size[0]}x{s.size[1]}, {s.frames_per_speed} pairs per "
             f"speed, {s.scenes} scenes x {s.cameras} cameras x {len(s.times)} times of day), rollcam's "
             f"`{s.model}` detector {start}, {n} seeds per cell "
             f"(mean ± sample std). `*`: the GS->RS difference exceeds twice its standard error over seeds "
             f"(with {n} seeds a rough test). " + _time_line(timing), "",
             "Made by:", "", "```sh norun", command, "```", "", "## Answers", ""]
    lines += [f"- {t}" for t in statements(agg) + label_statements(agg)]
    base = agg.get("base")
    if base:
        lines += ["", "The base model every run starts from, on the study's normal-speed test splits: " + ", ".join(
            f"{sh.upper()} mAP@0.5 {base[sh]['mAP50']:.3f}, mAP@0.5:0.95 {base[sh]['mAP50_95']:.3f} "
            f"(test SE {base[sh]['mAP50_95_se']:.3f})" for sh in SHUTTERS if sh in base) + "."]
    lines += ["", *_label_sections(s, agg, extra or {})]
    t1 = []
    for sp, row in agg["table1"].items():
        name = {"normal": "Normal", "fast": "Faster"}[sp]
        if not (row["gs"]["mAP50"]["n"] and row["rs"]["mAP50"]["n"]):
            continue  # not run (rollcam study --only), or not yet
        t1 += [f"| {name}_{sh.upper()} | " + " | ".join(_ms(row[sh][m]) for m in METRICS) + " |" for sh in SHUTTERS]
        t1.append("| GS->RS | " + " | ".join(_diff(row["gs_to_rs"][m]) for m in METRICS) + " |")
    if t1:
        lines += ["## Table 1 analogue: train and test on the same subset", "",
                  f"Study: {STUDY_REFERENCE['table1']}.", "",
                  "| Validation | P | R | mAP@0.5 | mAP@0.5:0.95 |", "|---|---:|---:|---:|---:|", *t1]
    t3 = []
    for sp, rows in agg["table3"].items():
        if not any(cells["gs"]["mAP50"]["n"] or cells["rs"]["mAP50"]["n"] for cells in rows.values()):
            continue
        t3 += [f"Walkers {_speed_label(sp)}:", "", "| train \\ test | GS | RS | GS+RS |", "|---|---:|---:|---:|"]
        for label, cells in rows.items():
            if not cells["gs"]["mAP50"]["n"] and not cells["rs"]["mAP50"]["n"]:
                continue
            t3.append(f"| {label} | " + " | ".join(f"{_ms(cells[t]['mAP50'])} / {_ms(cells[t]['mAP50_95'])}"
                                                    for t in ("gs", "rs", "gsrs")) + " |")
        t3.append("")
    if t3:  # a section only where the setting has its runs and some have finished
        lines += ["", "## Table 3 analogue: cross training (mAP@0.5 / mAP@0.5:0.95)", "",
                  "Study (mAP@0.5): " + ", ".join(f"{k} {v}" for k, v in STUDY_REFERENCE["table3_mAP50"].items())
                  + ".", "", *t3]
    rows = [(name, sp, row) for name, table in (("RGB", agg["speed"]), ("raw", agg["raw"]))
            for sp, row in table.items() if row["gs"]["mAP50"]["n"] and row["rs"]["mAP50"]["n"]]
    penalty = [f"| {name} | {_speed_label(sp)} | " + " | ".join(
               f"{_ms(row['gs'][m])} | {_ms(row['rs'][m])} | {_diff(row['gs_to_rs'][m])}"
               for m in ("mAP50", "mAP50_95")) + " |" for name, sp, row in rows]
    if any(name == "raw" or sp not in agg["table1"] for name, sp, _ in rows):  # more than Table 1 says
        lines += ["", "## RS penalty against walking speed", "",
                  "| input | speed | GS mAP@0.5 | RS mAP@0.5 | GS->RS | GS mAP@0.5:0.95 | RS mAP@0.5:0.95 | GS->RS |",
                  "|---|---|---:|---:|---:|---:|---:|---:|", *penalty]
    if any(len(pts) > 1 for pts in agg["fig4"].values()):
        lines += ["", f"## Fig. 4 analogue: training-set diversity ({s.fig4_subset}, seed {s.seeds[0]})", "",
                  "| varied | n | mAP@0.5 | mAP@0.5:0.95 |", "|---|---:|---:|---:|"]
        for k, pts in agg["fig4"].items():
            lines += [f"| {k} | {p['n']} | {p['mAP50']:.3f} | {p['mAP50_95']:.3f} |" for p in pts]
    lines += ["", "Charts: `report.png` (error bars: Table 1's the seed spread, the differences' one standard error, "
              "for mAP@0.5:0.95 with the test images' sampling added, for mAP@0.5 over the seeds alone). "
              "Numbers: `report.json`. Each run: `runs/<name>/` (a `rollcam train` folder with its card and curves, "
              "and `test.json`).", ""]
    return "\n".join(lines)


def _plot_label_arm(ax: Any, arms: dict[str, Any]) -> None:
    """The label arm's GS->RS change of mAP@0.5 and mAP@0.5:0.95 per arm and speed, with its standard error."""
    x = 0
    ticks, names = [], []
    for sp, row in arms.items():
        for arm in LABEL_ARMS:
            for j, m in enumerate(("mAP50", "mAP50_95")):
                d = row[arm]["gs_to_rs"][m]
                base = max(row["gs_model"][m]["mean"], 1e-9)
                ax.bar(x + 0.4 * j, 100 * (d["relative"] or 0.0), 0.4, yerr=_error_bar(d, base), capsize=3,
                       color=("C0", "C1")[j], label=("mAP@0.5", "mAP@0.5:0.95")[j] if x == 0 else None)
            ticks.append(x + 0.2)
            names.append(f"{sp}\n{arm}")
            x += 1
        x += 0.5
    ax.axhline(0, color="grey", lw=0.8)
    ax.set_xticks(ticks, names, fontsize=7)
    ax.set_ylabel("RS - GS (% of GS)")
    ax.set_title("Label arm: RS labels exact / gs / hand")
    _legend(ax, 7)


def _plot_penalty(ax: Any, agg: dict[str, Any]) -> None:
    """The RS penalty against walking speed: each speed's GS->RS change of mAP@0.5 and mAP@0.5:0.95, RGB and raw,
    with its standard error."""
    for name, table, style in (("RGB", agg["speed"], "o-"), ("raw", agg["raw"], "s--")):
        table = {sp: row for sp, row in table.items() if row["gs"]["mAP50"]["n"] and row["rs"]["mAP50"]["n"]}
        if not table:
            continue
        xs = [SPEED_X.get(sp) or float(sp) for sp in table]
        for m in ("mAP50", "mAP50_95"):
            ys = [100 * (row["gs_to_rs"][m]["relative"] or 0.0) for row in table.values()]
            err = [_error_bar(row["gs_to_rs"][m], row["gs"][m]["mean"]) for row in table.values()]
            ax.errorbar(xs, ys, yerr=err, fmt=style, capsize=3, label=f"{name} {m}")
    ax.axhline(0, color="grey", lw=0.8)
    ax.axhspan(-2, 2, color="grey", alpha=0.15)
    ax.set_xscale("log")
    ax.set_xlabel("walker speed (x normal)")
    ax.set_ylabel("RS - GS (% of GS)")
    ax.set_title("RS penalty against speed")
    _legend(ax, 7)


def plot_report(s: StudySettings, agg: dict[str, Any], path: Path) -> None:
    """Three panels: Table 1 bars, the RS penalty against speed (RGB and raw), Fig. 4; written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b, c) = plt.subplots(1, 3, figsize=(14, 4))
    labels, x = [], 0
    for sp, row in agg["table1"].items():
        for sh in SHUTTERS:
            for j, m in enumerate(("mAP50", "mAP50_95")):
                cell = row[sh][m]
                a.bar(x + 0.4 * j, cell["mean"], 0.4, yerr=cell["std"], color=("C0", "C1")[j], capsize=3,
                      label=("mAP@0.5", "mAP@0.5:0.95")[j] if x == 0 else None)
            labels.append(f"{sp}_{sh}")
            x += 1
    a.set_xticks([i + 0.2 for i in range(len(labels))], labels, fontsize=8)
    a.set_ylim(0, 1)
    a.set_title("Table 1: train = test subset")
    _legend(a, 8)
    _plot_penalty(b, agg)
    arms = {sp: row for sp, row in agg.get("label_arm", {}).items() if row["gs_model"]["mAP50"]["n"]}
    if arms and all(len(pts) <= 1 for pts in agg["fig4"].values()):
        _plot_label_arm(c, arms)  # a study without Fig. 4's reduced runs shows the label arm there instead
    else:
        for k, style in (("scenes", "o-"), ("cameras", "s--")):
            pts = agg["fig4"][k]
            for m in ("mAP50", "mAP50_95"):
                c.plot([p["n"] for p in pts], [p[m] for p in pts], style, label=f"{m} vs {k}")
        c.set_xlabel("training scenes / camera views")
        c.set_ylim(0, 1)
        c.set_title(f"Fig. 4: diversity ({s.fig4_subset})")
        _legend(c, 7)
    for ax in (a, b, c):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    write_figure(path, fig, dpi=100)


def _error_bar(d: dict[str, Any], gs_mean: float) -> float:
    """A difference's error bar in % of GS: one standard error, with the test images' sampling where the
    difference has it (``se_images``, mAP@0.5:0.95), else over the seeds alone."""
    return 100 * d.get("se_images", d["se"]) / max(gs_mean, 1e-9)


def _legend(ax: Any, fontsize: int) -> None:
    """The chart's legend, when it has something labelled (a partial study's chart may not yet)."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=fontsize)


def write_report(root: Path, s: StudySettings, results: list[dict[str, Any]], timing: dict[str, Any],
                 command: str | None = None, extra: dict[str, Any] | None = None,
                 runs: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    """Write ``report.json``, ``report.md`` and ``report.png`` under ``root``; return the JSON document.
    ``extra``: the tables made without training (``coco``: Table 2; ``labels``: box sizes and label ceilings) and
    what carries the study on (``datasets``, ``base_sha256``). ``runs``: what ``report.json`` lists (every
    finished run), when more than the ``results`` the tables are made of."""
    agg = aggregate(s, results)
    extra = extra or {}
    command = command or f"rollcam study --setting {s.name} --out {root.name}"
    doc = {"kind": "rollcam-study", "settings": s.to_json(), "timing": timing, "command": command,
           "study_reference": STUDY_REFERENCE, "answers": statements(agg) + label_statements(agg), **agg, **extra,
           "runs": sorted(results if runs is None else runs, key=lambda r: r["job"]["key"])}
    write_atomic(root / "report.json", (json.dumps(doc, indent=1) + "\n").encode())
    write_atomic(root / "report.md", report_markdown(s, agg, timing, command, extra).encode())
    plot_report(s, agg, root / "report.png")
    return doc
