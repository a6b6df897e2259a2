"""``rollcam capture``: frames of SOURCE to image files and frames.jsonl.

The work is ``rollcam.host.recording.capture``."""

from __future__ import annotations

import argparse
import json
import sys

from rollcam.common.errors import EXIT_INTERRUPTED
from rollcam.common.values import positive_int

from . import PROG, Subparsers, value_type


def add_parser(sub: Subparsers) -> argparse.ArgumentParser:
    """Add ``rollcam capture``."""
    p = sub.add_parser("capture", help="capture frames and their ground truth to image files and frames.jsonl",
                       description="Capture N frames of SOURCE into DIR: images NNNNNN_rs.png / NNNNNN_gs.png "
                                   "(NNNNNN.png from a camera whose shutter is unknown), DIR/frames.jsonl (one JSON "
                                   "record per image) and DIR/capture.json. Nothing is written before the source "
                                   "and options are accepted.",
                       epilog="SOURCE examples: 'emu:imx219?scene=street&speed=fast', 'emu:letsroll?size=960x540"
                              "&seed=3', 'file:clips/hfr?fps=960&line_time_ns=30864'. Quote URIs in the shell.")
    p.add_argument("source", metavar="SOURCE", help="source URI, e.g. 'emu:imx219?scene=street'")
    p.add_argument("--frames", type=value_type(positive_int, "an integer >= 1"), required=True, metavar="N",
                   help="instants to capture")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--shutter", choices=("rolling", "global", "both"), default=None,
                   help="'both' stores GS and RS frames of the same instants (default: the source's shutter)")
    p.add_argument("--format", choices=("png", "jpg", "npy", "mcap", "ros2bag", "rosbag1", "kalibr", "mp4"),
                   default="png",
                   help="image file format (default: png; raw frames go losslessly into png or npy), or one "
                        "recording of the whole capture: mcap (ROS 2 messages, DIR/capture.mcap), ros2bag "
                        "(DIR/capture_ros2/), rosbag1 (DIR/capture.bag), kalibr (ROS 1 bag with Kalibr's "
                        "/cam0/image_raw and /imu0 only, DIR/kalibr.bag), mp4 (H.264 DIR/capture.mp4 and, with an "
                        "IMU, Gyroflow's DIR/capture.gcsv); the bag formats need the robotics extra")
    p.add_argument("--bag-storage", choices=("sqlite3", "mcap"), default="sqlite3",
                   help="storage of --format ros2bag (default: sqlite3, rosbag2's default)")
    p.add_argument("--overwrite", action="store_true", help="replace an earlier capture in DIR")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("--progress", action="store_true", help="show progress even when stderr is not a terminal")
    return p


def run(args: argparse.Namespace) -> int:
    """Capture; 130 after Ctrl-C with every complete frame kept."""
    from ..recording.capture import CaptureInterrupted, capture
    from ..sources import open_camera
    from .compile_notice import notify_if_cold, renders

    if renders(args.source):
        notify_if_cold()
    with open_camera(args.source) as source:
        try:
            result = capture(source, args.out, args.frames, shutter=args.shutter, fmt=args.format,
                             overwrite=args.overwrite, progress=True if args.progress else None,
                             command=[PROG, *args.argv], bag_storage=args.bag_storage)
        except CaptureInterrupted as exc:
            r = exc.result
            kept = r.recording if r.recording is not None else r.out_dir / "frames.jsonl"
            print(f"{PROG}: interrupted: kept {r.frames} complete frame(s) in {kept}", file=sys.stderr)
            if args.json:
                print(json.dumps(r.to_json()))
            return EXIT_INTERRUPTED
    if args.json:
        print(json.dumps(result.to_json()))
    else:
        short = "" if result.complete else f" (source ended after {result.frames} of {args.frames})"
        if result.recording is not None:
            print(f"recorded {result.frames} frame(s) in {result.recording} in {result.seconds:.1f} s{short}")
        else:
            print(f"wrote {result.frames} frame(s), {result.images} image(s) to {result.out_dir}/ in "
                  f"{result.seconds:.1f} s{short}; metadata in {result.out_dir / 'frames.jsonl'}")
    return 0
