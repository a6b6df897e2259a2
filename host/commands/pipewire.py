"""``rollcam pipewire [SOURCE]``: the emulated camera as a PipeWire ``Video/Source`` node in a private, headless
PipeWire (``rollcam.host.servers.pipewire``), until Ctrl-C."""

from __future__ import annotations

import argparse
import json
import tempfile
import threading

from . import Subparsers


def add_parser(sub: Subparsers) -> argparse.ArgumentParser:
    """Add ``rollcam pipewire``."""
    p = sub.add_parser("pipewire", help="publish the camera as a PipeWire Video/Source node (a private PipeWire)",
                       description="Start a private, headless PipeWire (and WirePlumber) whose own V4L2 source "
                                   "reads the emulated camera, so it is a Video/Source node for any PipeWire client "
                                   "given XDG_RUNTIME_DIR=RUNTIME_DIR (pipewiresrc, pw-cat, pw-dump). Prints one JSON "
                                   "line (node name and id, runtime folder) when the node is up; runs until Ctrl-C.",
                       epilog="Example: rollcam pipewire 'emu:imx219?size=640x480&scene=street' --runtime-dir "
                              "/tmp/rollcam-pw, then XDG_RUNTIME_DIR=/tmp/rollcam-pw gst-launch-1.0 pipewiresrc "
                              "target-object=rollcam ! videoconvert ! autovideosink")
    p.add_argument("source", nargs="?", default="emu:imx219?size=640x480",
                   help="an emu: URI or a sensor name (default: emu:imx219?size=640x480)")
    p.add_argument("--name", default="rollcam", help="the node's node.name (default: rollcam)")
    p.add_argument("--runtime-dir", default=None, metavar="DIR",
                   help="the private PipeWire's XDG_RUNTIME_DIR (default: a new temporary folder)")
    p.add_argument("--seconds", type=float, default=None, help="stop after this long (default: at Ctrl-C)")
    return p


def run(args: argparse.Namespace) -> int:
    """Publish the node and hold it until Ctrl-C (or ``--seconds``)."""
    from ..servers.pipewire import PipeWireCamera

    runtime = args.runtime_dir or tempfile.mkdtemp(prefix="rollcam-pw-")
    with PipeWireCamera(args.source, runtime, name=args.name) as camera:
        node = camera.node()
        print(json.dumps({"node": args.name, "id": node["id"], "media.class": "Video/Source",
                          "XDG_RUNTIME_DIR": str(runtime)}), flush=True)
        threading.Event().wait(args.seconds)
    return 0
