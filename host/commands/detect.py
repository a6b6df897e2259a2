"""``rollcam detect SOURCE --detector NAME``: live detection, logged and annotated.

The loop: ``rollcam.host.detectors.live``."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from rollcam.common.errors import EXIT_INTERRUPTED, ConfigError
from rollcam.common.files import output_dir
from rollcam.common.values import fraction, non_negative_float, positive_fraction, positive_int

from . import PROG, Subparsers, value_type


def add_parser(sub: Subparsers) -> argparse.ArgumentParser:
    """Add ``rollcam detect``."""
    p = sub.add_parser(
        "detect", help="run a detector on a source live: fps, latencies, detections.jsonl, annotated MP4",
        description="Run a detector on SOURCE frame by frame, showing fps, capture and detector latency, and "
                    "for synthetic sources running precision/recall against the GS and RS ground truth. With --out, "
                    "write DIR/detections.jsonl, DIR/detections.mp4 and DIR/detect.json. Ctrl-C stops cleanly "
                    "(exit 130) keeping everything written.",
        epilog="Detectors: 'hog', 'ssdlite' (packaged SSDLite-MobileNetV2 person model), 'personnet' (rollcam's "
               "own person model, trained on its GS/RS renders), 'onnx:MODEL.onnx' (YOLO or SSD exports); options "
               "follow '?', e.g. 'ssdlite?conf=0.4&tiles=3x2'.")
    p.add_argument("source", metavar="SOURCE", help="source URI, e.g. 'emu:imx219?scene=street&speed=fast'")
    p.add_argument("--detector", required=True, metavar="NAME",
                   help="detector spec (hog, ssdlite, personnet, onnx:PATH)")
    p.add_argument("--frames", type=value_type(positive_int, "an integer >= 1"), default=None, metavar="N",
                   help="stop after N frames")
    p.add_argument("--out", default=None, metavar="DIR", help="write detections.jsonl, detections.mp4, detect.json")
    p.add_argument("--no-video", action="store_true", help="skip the annotated MP4")
    p.add_argument("--overwrite", action="store_true", help="replace an earlier run in DIR")
    p.add_argument("--shutter", choices=("rolling", "global"), default=None,
                   help="read this shutter from sources that render both (default: the source's)")
    p.add_argument("--correct", choices=("gyro", "flow"), default=None,
                   help="correct the rolling shutter on the host before detecting: gyro (per-row rotational "
                        "unwarp from the frames' IMU samples; the source needs imu=on) or flow (optional, for "
                        "object motion: dense optical flow from the previous frame; approximate)")
    p.add_argument("--iou", type=value_type(positive_fraction, "a number in (0, 1]"), default=0.5,
                   help="IoU for matching ground truth, in (0, 1] (default: %(default)s)")
    p.add_argument("--min-height", type=value_type(non_negative_float, "a number of pixels >= 0"), default=0.0,
                   metavar="PX",
                   help="truth boxes shorter than this are ignored, not counted as missed (default: %(default)s)")
    p.add_argument("--min-visible", type=value_type(fraction, "a number in [0, 1]"), default=0.25, metavar="F",
                   help="truth boxes less visible than this fraction, in [0, 1], are ignored (default: %(default)s)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--progress", action="store_true", help="show the status line even when stderr is no terminal")
    return p


def run(args: argparse.Namespace) -> int:
    """Run the loop and print the summary; 130 after Ctrl-C with everything kept."""
    from ..detectors import load_detector
    from ..detectors.live import LOG, DetectInterrupted, StatusLine, run_detect
    from ..evaluation.truthmatch import RunningPR
    from ..sources import open_camera
    from .compile_notice import notify_if_cold, renders

    out_dir = output_dir(args.out, make=False) if args.out else None  # a file there: exit 2 before any work
    if out_dir is not None and (out_dir / LOG).exists() and not args.overwrite:
        raise ConfigError(f"{str(out_dir)!r} already holds a detection run ({LOG}); pass --overwrite or choose "
                          "another --out")
    truth = RunningPR(iou=args.iou, min_height_px=args.min_height, min_visible=args.min_visible)
    detector = load_detector(args.detector)
    if renders(args.source):
        notify_if_cold()
    status = StatusLine(args.frames, enabled=True if args.progress else None)
    try:
        with open_camera(args.source) as source:
            try:
                result = run_detect(source, detector, frames=args.frames, out_dir=out_dir, shutter=args.shutter,
                                    video=not args.no_video, truth=truth, status=status,
                                    meta={"command": [PROG, *args.argv]}, correct=args.correct)
            except DetectInterrupted as exc:
                status.close()
                _print_summary(exc.result, args, interrupted=True)
                return EXIT_INTERRUPTED
    finally:
        status.close()
        detector.close()
    _print_summary(result, args)
    return 0


def _print_summary(result: Any, args: argparse.Namespace, interrupted: bool = False) -> None:
    from ..detectors.live import LOG, SUMMARY, VIDEO, summary_stats

    if args.json:
        print(json.dumps(result.to_json()))
        return
    how = "interrupted after" if interrupted else "ran"
    cap, det = summary_stats(result.capture_ms), summary_stats(result.detect_ms)
    lines = [f"{how} {result.frames} frame(s) in {result.seconds:.1f} s ({result.fps:.2f} fps), "
             f"{result.detections} detection(s)"]
    if cap and det:
        lines.append(f"capture {cap['mean']:.1f} ms (p95 {cap['p95']:.1f}), detector {det['mean']:.1f} ms "
                     f"(p95 {det['p95']:.1f}) per frame")
    if result.truth is not None and result.truth.frames:
        lines.append(f"against ground truth (IoU >= {result.truth.iou}): {result.truth.summary()}")
    if result.out_dir is not None:
        lines.append(f"wrote {result.out_dir / LOG}" + ("" if args.no_video else f", {result.out_dir / VIDEO}")
                     + f", {result.out_dir / SUMMARY}")
    print("\n".join(lines), file=sys.stderr if interrupted else sys.stdout)
