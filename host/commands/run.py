"""``rollcam run [--device PATH=SOURCE ...] -- PROGRAM ARGS...``: a program sees emulated /dev/videoN nodes
(no kernel module, no root: ``rollcam.host.servers.devnodes``)."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add ``rollcam run``."""
    p = sub.add_parser("run", help="run a program that sees emulated /dev/videoN V4L2 devices",
                       description="Run PROGRAM with emulated V4L2 capture devices at the given paths (default: "
                                   "/dev/video0 = emu:imx219?size=640x480), through a preloaded library: no kernel "
                                   "module and no root. Programs that bypass libc (static binaries) see nothing. "
                                   "The exit status is PROGRAM's.",
                       epilog="Example: rollcam run --device /dev/video0=emu:imx219?size=640x480&scene=street -- "
                              "v4l2-ctl --all")
    p.add_argument("--device", action="append", default=[], metavar="PATH=SOURCE",
                   help="a device node and its camera: an emu: URI or a sensor name (repeatable; a bare SOURCE "
                        "takes the next /dev/videoN)")
    p.add_argument("program", nargs=argparse.REMAINDER, metavar="-- PROGRAM ARGS", help="the program to run")
    return p


def run(args: argparse.Namespace) -> int:
    """Serve the devices while PROGRAM runs; PROGRAM's exit status."""
    from ..servers.devnodes import DEFAULT_DEVICE, DEFAULT_SOURCE, parse_device, run_program

    argv = args.program[1:] if args.program[:1] == ["--"] else args.program
    devices = [parse_device(d, i) for i, d in enumerate(args.device)] or [(DEFAULT_DEVICE, DEFAULT_SOURCE)]
    return run_program(devices, argv)
