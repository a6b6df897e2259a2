"""``rollcam calibrate``: line time and camera-IMU time offset of a capture.

The work: ``rollcam.host.correction.calibrate``."""

from __future__ import annotations

import argparse
import json

from rollcam.common.values import finite_float, positive_int

from . import Subparsers, value_type


def add_parser(sub: Subparsers) -> argparse.ArgumentParser:
    """Add ``rollcam calibrate``."""
    p = sub.add_parser("calibrate", help="estimate the rolling-shutter line time and camera-IMU time offset",
                       description="Estimate the rolling-shutter line time and the camera-IMU time offset "
                                   "(Kalibr's line_delay and timeshift_cam_imu) of the camera a capture came from, "
                                   "from its images and imu.csv alone: feature tracks aligned with the gyro. "
                                   "Writes DIR/camchain-imucam.yaml (or --out).",
                       epilog="Capture with an IMU and a rotating camera, e.g. rollcam capture "
                              "'emu:imx219?ego=calib&pedestrians=0&imu_offset_us=250' --frames 30 --out cap")
    p.add_argument("capture", metavar="DIR", help="a folder rollcam capture wrote (with imu.csv)")
    p.add_argument("--max-offset-ms", type=value_type(finite_float, "a number"), default=20.0, metavar="MS",
                   help="search the offset in -MS..MS (default 20)")
    p.add_argument("--gaps", type=value_type(positive_int, "an integer >= 1"), default=3, metavar="G",
                   help="track each image into the next G images (default 3)")
    p.add_argument("--out", default=None, metavar="FILE", help="result YAML (default DIR/camchain-imucam.yaml)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    return p


def run(args: argparse.Namespace) -> int:
    """Calibrate and write the result file."""
    from pathlib import Path

    from rollcam.common.errors import ConfigError
    from rollcam.common.files import write_atomic

    from ..correction.calibrate import RESULT_YAML, calibrate, result_yaml

    if not args.max_offset_ms > 0:
        raise ConfigError(f"--max-offset-ms must be > 0, got {args.max_offset_ms!r}")
    cal = calibrate(args.capture, max_offset_s=args.max_offset_ms * 1e-3, gaps=tuple(range(1, args.gaps + 1)))
    out = Path(args.out) if args.out else Path(args.capture) / RESULT_YAML
    write_atomic(out, result_yaml(args.capture, cal).encode())
    if args.json:
        print(json.dumps({**cal.to_json(), "out": str(out)}))
    else:
        print(f"{cal}\nwrote {out}")
    return 0
