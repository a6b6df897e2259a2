"""``rollcam gadget SENSOR``: the emulated camera as a real USB webcam, through Linux's UVC gadget function.

On a board with a USB device controller (Raspberry Pi Zero 2 W / 4 / 5 and others: docs/gadget.md), as root:
the camera's formats go into configfs (``rollcam.emu.gadget``), the gadget is bound to the controller, and any
computer the board is plugged into sees a UVC camera streaming the frames ``rollcam emulate`` makes of the
same options. The camera flags are ``rollcam emulate``'s; the HTTP and serial doors work beside the gadget.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from . import Subparsers
from .emulate import add_camera_flags, add_door_flags, add_run_flags, add_usb_id_flag, camera_options


def add_parser(sub: Subparsers) -> argparse.ArgumentParser:
    """Add ``rollcam gadget``: the sensor, the camera flags, the UDC, the USB IDs and the doors."""
    p = sub.add_parser("gadget", help="be a USB webcam (UVC) through the kernel's gadget function (as root)",
                       description="Make this board's USB device port a UVC camera streaming the emulated sensor "
                                   "(Linux's usb_f_uvc through configfs; needs root, libcomposite and a USB device "
                                   "controller), until Ctrl-C. The HTTP and serial doors can run beside it.",
                       epilog="Example: sudo rollcam gadget imx219 --scene street --size 640x480 --serial")
    p.add_argument("sensor", metavar="SENSOR", help="sensor name (see 'rollcam list') or a .yaml path")
    add_camera_flags(p)
    g = p.add_argument_group("USB gadget")
    g.add_argument("--udc", default=None, metavar="NAME",
                   help="USB device controller to bind, a name in /sys/class/udc (default: the only one there)")
    add_usb_id_flag(g, "gadget")
    g.add_argument("--frame-log", type=Path, default=None, metavar="PATH",
                   help="append one JSON line per frame sent (sequence, format, size, bytes, SHA-1) to PATH, to "
                        "match what a host captured with the emulator's frames")
    doors = p.add_argument_group("doors beside the gadget")
    add_door_flags(doors, "off unless given")
    add_run_flags(p)
    return p


def run(args: argparse.Namespace) -> int:
    """Serve the gadget (and the doors asked for) until Ctrl-C, SIGTERM or ``--duration``."""
    from rollcam.common.faults import FaultPlan

    from ..servers.emulate import GADGET_TRANSPORTS, serve

    args.faults = FaultPlan()  # the gadget's stream is the kernel's: no faults to inject on it
    return serve(args, camera_options(args), GADGET_TRANSPORTS, "rollcam gadget")
