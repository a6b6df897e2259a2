"""``rollcam view SOURCE``: the live page for any source (a camera, a file, a stream), served host side."""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading

from rollcam.common.values import JPEG_QUALITY, jpeg_quality, non_negative_float, parse_host_port

from . import Subparsers, value_type

DEFAULT_BIND = "127.0.0.1:8081"


def add_parser(sub: Subparsers) -> argparse.ArgumentParser:
    """Add ``rollcam view``."""
    p = sub.add_parser("view", help="open the live page (stream, truth, row timing, detections) for any source",
                       description="Serve the live view of SOURCE in the browser: the stream, overlays of its ground "
                                   "truth and detections, a row-timing ruler, per-frame metadata, a plot of frame "
                                   "intervals and the controls the source has. The same page as 'rollcam emulate "
                                   "--http'. Bound beyond loopback, the page needs the token printed at start.",
                       epilog="Example: rollcam view 'emu:imx219?scene=street&speed=fast' --detector hog")
    p.add_argument("source", metavar="SOURCE", help="source URI (emu:, file:, http://, v4l2:, opencv:, uvc:, oak:)")
    p.add_argument("--detector", default=None, metavar="SPEC", help="draw this detector's boxes (hog, ssdlite, "
                                                                    "onnx:PATH)")
    p.add_argument("--http", type=value_type(parse_host_port, "HOST:PORT"), default=parse_host_port(DEFAULT_BIND),
                   metavar="HOST:PORT", help=f"where to serve the page (default: {DEFAULT_BIND})")
    p.add_argument("--quality", type=value_type(jpeg_quality), default=JPEG_QUALITY, metavar="Q",
                   help="JPEG quality of the page's stream, 1..100 (default: %(default)s)")
    p.add_argument("--unpaced", action="store_true", help="show recorded or emulated frames as fast as they are "
                                                          "read (default: at their timestamps' rate)")
    p.add_argument("--duration", type=value_type(non_negative_float, "a number of seconds >= 0"), default=None,
                   metavar="SECONDS", help="stop after this long (0: as soon as the page is served)")
    return p


def run(args: argparse.Namespace) -> int:
    """Serve until Ctrl-C, SIGTERM or ``--duration``."""
    from rollcam.common.lifecycle import Deadline

    from ..detectors import load_detector
    from ..servers.view import open_view
    from ..sources import open_camera

    detector = load_detector(args.detector) if args.detector else None
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        source = open_camera(args.source)
        host, port = args.http
        with open_view(source, host, port, quality=args.quality, detector=detector,
                       paced=not args.unpaced) as running:
            auth = "   (token required: bound beyond loopback)" if running.view.token else ""
            print(f"viewing {args.source}", flush=True)
            print(f"  live view:     {running.view.url}{auth}", flush=True)
            print(f"  MJPEG stream:  {running.server.url}", flush=True)
            print("press Ctrl-C to stop", flush=True)
            deadline = Deadline(args.duration)
            with contextlib.suppress(KeyboardInterrupt):
                while not stop.wait(deadline.within(0.5)) and not deadline.expired:
                    running.pump.check()
                    running.server.check()
            print(f"stopped; {running.pump.stats.frames} frames shown", file=sys.stderr)
    finally:
        signal.signal(signal.SIGTERM, previous)
        if detector is not None:
            detector.close()
    return 0
