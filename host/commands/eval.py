"""``rollcam eval``: a detector (or a detections file) against a dataset's labels, per shutter and speed."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rollcam.common.errors import ConfigError
from rollcam.common.files import output_dir

from . import Subparsers

DESCRIPTION = """\
Evaluate a detector on the GS and RS images of a rollcam dataset (or on an Ultralytics data.yaml or a COCO
JSON) and report P, R, mAP@0.5 and mAP@0.5:0.95 per speed and shutter, as the study's tables do, with the
GS->RS difference. mAP comes from faster-coco-eval (COCO rules; ignore regions are iscrowd); P and R are read
at the confidence of best mean F1, as Ultralytics reports them. Instead of a detector, --detections takes a
file of your own model's outputs (rollcam detections.jsonl or a COCO results JSON). Results go to
OUT/DETECTOR_SPLIT.json and .png; with --subset NAME to OUT/DETECTOR_SPLIT_NAME.json and .png, so evaluating
one subset never replaces the results of all of them. --correct gyro adds the study's baseline pipeline: the
RS images against the GS labels and gyro-corrected from the IMU block each sample's record keeps (a dataset
built with --source-options imu=on), to OUT/DETECTOR_SPLIT_gyro.json."""


def add_parser(sub: Subparsers) -> argparse.ArgumentParser:
    """Add ``rollcam eval``."""
    p = sub.add_parser("eval", help="P, R, mAP@0.5 and mAP@0.5:0.95 of a detector per shutter and speed",
                       description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dataset", metavar="DATASET", help="rollcam dataset folder, YOLO data.yaml (or its folder), "
                   "or COCO JSON file")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--detector", metavar="SPEC", help="detector spec, e.g. hog or 'onnx:model.onnx?conf=0.25'; "
                     "insensor:NET takes what the emulated camera's in-sensor network NET sends for each image "
                     "(a rollcam dataset: its records re-make the frames)")
    src.add_argument("--detections", metavar="FILE", help="detections.jsonl or a COCO results JSON")
    p.add_argument("--split", default="test", help="split to evaluate (default: test)")
    p.add_argument("--subset", default=None, metavar="NAME", help="evaluate one subset only, e.g. normal_rs")
    p.add_argument("--images", default=None, metavar="DIR",
                   help="folder the COCO JSON's file names are relative to (default: its folder, or the folder "
                        "above when it lies in annotations/)")
    p.add_argument("--out", default=None, metavar="DIR", help="folder for the result JSON and chart "
                   "(default: DATASET/eval/ for a folder, else rollcam_out/eval)")
    p.add_argument("--save-detections", default=None, metavar="FILE", help="also write the detector's detections "
                   "as detections.jsonl (to re-evaluate without inference)")
    p.add_argument("--correct", default=None, metavar="gyro",
                   help="also evaluate the RS images against the GS labels, and gyro-corrected (rows RS_GSBOX, "
                        "RS_GYRO); the dataset needs IMU blocks (rollcam dataset --source-options imu=on)")
    p.add_argument("--json", action="store_true", help="print one JSON document instead of the table")
    p.add_argument("--progress", action="store_true", help="show progress even when stderr is not a terminal")
    return p


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text)[:60]


def result_stem(detector: str | None, detections: str | None, split: str, subset: str | None,
                correct: str | None = None) -> str:
    """File stem of one evaluation's results: DETECTOR_SPLIT, DETECTOR_SPLIT_SUBSET for one subset, and
    ``_CORRECTION`` after either with ``--correct``."""
    stem = f"{_slug(detector or Path(detections or 'detections').stem)}_{_slug(split)}"
    stem = stem if subset is None else f"{stem}_{_slug(subset)}"
    return stem if correct is None else f"{stem}_{_slug(correct)}"


def run(args: argparse.Namespace) -> int:
    """Evaluate, write the result JSON and chart atomically, print the table (or the JSON)."""
    from rollcam.common.files import write_atomic

    from ..evaluation.report import format_table, plot
    from ..evaluation.run import evaluate_dataset

    doc = evaluate_dataset(args.dataset, detector=args.detector, detections=args.detections, split=args.split,
                           subset=args.subset, images=args.images, save_detections=args.save_detections,
                           progress=True if args.progress else None, correct=args.correct)
    if not any(doc["results"].values()) and not doc["sets"]:
        raise ConfigError("nothing was evaluated")
    ds = Path(args.dataset)
    out = Path(args.out) if args.out else (ds / "eval" if ds.is_dir() else Path("rollcam_out/eval"))
    output_dir(out)
    stem = result_stem(args.detector, args.detections, args.split, args.subset, args.correct)
    doc["files"] = {"json": str(out / f"{stem}.json"), "chart": str(out / f"{stem}.png")}
    write_atomic(out / f"{stem}.json", (json.dumps(doc, indent=1) + "\n").encode())
    plot(doc, out / f"{stem}.png")
    if args.json:
        print(json.dumps(doc))
    else:
        print(format_table(doc))
        print(f"metric time {doc['timing']['metrics_s']:.3f} s (inference {doc['timing']['inference_s']:.1f} s); "
              f"chart {out / (stem + '.png')}")
    return 0
