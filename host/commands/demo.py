"""``rollcam demo``: a short emulated street video and a GS/RS contact sheet.

The work is ``rollcam.host.recording.demo``."""

from __future__ import annotations

import argparse

from rollcam.common.values import parse_size, positive_float

from . import Subparsers, value_type


def add_parser(sub: Subparsers) -> argparse.ArgumentParser:
    """Add ``rollcam demo``."""
    p = sub.add_parser("demo", help="render a short emulated rolling-shutter street: MP4 and contact sheet",
                       description="Stream a few seconds of an emulated street scene with fast walkers; write an "
                                   "MP4 of the stream with GS and RS boxes and a PNG contact sheet of GS/RS pairs "
                                   "of the same instants. A global-shutter sensor (e.g. --sensor ov9281) shows no "
                                   "skew: its frames and boxes are global-shutter ones.")
    p.add_argument("--out", default="rollcam_out/demo", help="output folder (default: %(default)s)")
    p.add_argument("--seconds", type=value_type(positive_float, "a number of seconds > 0"), default=2.0,
                   help="stream time to render, in seconds (default: %(default)s)")
    p.add_argument("--sensor", default="letsroll", help="emulated sensor (see 'rollcam list'; default: %(default)s)")
    p.add_argument("--size", type=value_type(parse_size), default=None,
                   help="output WxH (default: the sensor's default mode halved to at most 960 wide)")
    p.add_argument("--progress", action="store_true", help="show progress even when stderr is not a terminal")
    return p


def run(args: argparse.Namespace) -> int:
    """Render the demo and print where its files are."""
    from ..recording.demo import default_size, run_demo
    from .compile_notice import notify_if_cold

    size = args.size or default_size(args.sensor)  # checks the sensor name before any notice
    notify_if_cold()
    result = run_demo(args.out, seconds=args.seconds, sensor=args.sensor, size=size,
                      progress=True if args.progress else None)
    print(f"video:         {result.video}")
    print(f"contact sheet: {result.contact_sheet}")
    print(f"source:        {result.uri}")
    print(result.summary())
    return 0
