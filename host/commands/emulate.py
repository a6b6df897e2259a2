"""``rollcam emulate SENSOR``: serve an emulated camera until Ctrl-C (the servers: ``rollcam.host.servers.emulate``).

The camera flags are generated from ``rollcam.firmware.options.OPTIONS``, one per option of the ``emu:`` URI,
checked by the table's own parser and handed to it as text, so a value means and is checked the same as in an
``emu:`` URI. The transport flags name what ``rollcam.host.servers.emulate.TRANSPORTS`` starts (a new transport is its
flags here and its starter there).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

from rollcam.common.errors import ConfigError
from rollcam.common.faults import FaultPlan
from rollcam.common.values import (
    JPEG_QUALITY,
    finite_float,
    jpeg_quality,
    non_negative_float,
    non_negative_int,
    parse_bool,
    parse_host_port,
    parse_size,
    positive_float,
    usb_id,
)

from . import Subparsers, value_type

DEFAULT_HTTP = "127.0.0.1:8080"
TRANSPORT_FLAGS = ("http", "serial", "usbip")
"""The transport options (their dests); with none given, HTTP on ``DEFAULT_HTTP``."""
FLAG_NAMES = {"serial": "serial-number"}
"""Camera options whose flag is not ``--<name>`` (``--serial`` is the serial transport)."""
_EXPECTED = {finite_float: "a number", positive_float: "a number > 0", non_negative_float: "a number >= 0",
             non_negative_int: "an integer >= 0", parse_size: "WIDTHxHEIGHT", parse_bool: "on or off"}
_HOST_PORT = value_type(parse_host_port, "HOST:PORT")


def add_parser(sub: Subparsers) -> argparse.ArgumentParser:
    """Add ``rollcam emulate``: the sensor, one flag per camera option, the transports."""
    p = sub.add_parser("emulate", help="serve an emulated camera over HTTP (MJPEG), a serial pty and USB/IP (UVC)",
                       description="Stream an emulated sensor in real time and serve it until Ctrl-C: MJPEG over "
                                   f"HTTP (--http, default {DEFAULT_HTTP}), the serial control protocol on a "
                                   "pseudo-terminal (--serial) and a UVC camera over USB/IP (--usbip).",
                       epilog="Example: rollcam emulate imx219 --scene street --speed fast --http 127.0.0.1:8080 "
                              "--serial")
    p.add_argument("sensor", metavar="SENSOR", help="sensor name (see 'rollcam list') or a .yaml path")
    add_camera_flags(p)
    g = p.add_argument_group("transports")
    add_door_flags(g, f"default when no transport is given: {DEFAULT_HTTP}")
    g.add_argument("--usbip", type=_HOST_PORT, default=None, metavar="HOST:PORT",
                   help="serve the camera as a UVC device over USB/IP (the usbip protocol port is 3240)")
    g.add_argument("--usb-transfer", choices=("iso", "bulk"), default="iso",
                   help="UVC streaming endpoint type for --usbip (default: %(default)s)")
    add_usb_id_flag(g, "--usbip camera")
    p.add_argument("--faults", type=value_type(FaultPlan.parse, "a fault plan like drop=2%,error=1%,seed=7"),
                   default=FaultPlan(), metavar="PLAN",
                   help="inject faults on every transport, reproducibly by seed, e.g. 'drop=2%%,stall=1%%,"
                        "disconnect=300,seed=7' (docs/faults.md lists the keys and what each transport does)")
    p.add_argument("--rig", type=value_type(_rig, "a rig like stereo,baseline=0.12,sync=hw,offset_ns=0/1500"),
                   default=None, metavar="RIG",
                   help="emulate every camera of a multi-camera rig of one scene, camera i on each transport's port "
                        "+ i: 'stereo,baseline=0.12' or 'surround,n=4', sync=hw|free, per-camera offset_ns=, ppm=, "
                        "jitter_ns= (one value or one per camera joined by '/'), seed= (docs/rigs.md)")
    add_run_flags(p)
    return p


def add_door_flags(g: Any, http_default: str) -> None:
    """The HTTP and serial doors' flags (``rollcam emulate``, ``rollcam gadget``) on ``g``, a parser or group."""
    g.add_argument("--http", type=_HOST_PORT, default=None, metavar="HOST:PORT",
                   help=f"serve MJPEG over HTTP and the live view at / ({http_default}; beyond loopback the view "
                        "needs the token printed at start)")
    g.add_argument("--quality", type=value_type(jpeg_quality), default=JPEG_QUALITY, metavar="Q",
                   help="JPEG quality of the HTTP stream, 1..100 (default: %(default)s)")
    g.add_argument("--detector", default=None, metavar="SPEC",
                   help="draw this detector's boxes on the live view (hog, ssdlite, onnx:PATH; needs --http)")
    g.add_argument("--serial", action="store_true", help="serve the control protocol on a pseudo-terminal")


def add_usb_id_flag(g: Any, what: str) -> None:
    """``--usb-id VID:PID`` of a USB camera."""
    g.add_argument("--usb-id", type=value_type(usb_id, "VID:PID in hex"), default=None, metavar="VID:PID",
                   help=f"USB vendor and product ID of the {what}, in hex (default: 1209:0001, a pid.codes test "
                        "ID; give a real camera's to test a driver quirk for it)")


def add_run_flags(p: argparse.ArgumentParser) -> None:
    """``--duration`` and ``--json`` of a serving command."""
    p.add_argument("--duration", type=value_type(non_negative_float, "a number of seconds >= 0"), default=None,
                   metavar="SECONDS", help="stop after this long (0: as soon as every server is up)")
    p.add_argument("--json", action="store_true", help="print the endpoints as one JSON line")


def run(args: argparse.Namespace) -> int:
    """Serve until Ctrl-C, SIGTERM or ``--duration``."""
    from ..servers.emulate import serve

    if not any(getattr(args, name) for name in TRANSPORT_FLAGS):
        args.http = parse_host_port(DEFAULT_HTTP)
    return serve(args, camera_options(args))


def _rig(text: str) -> Any:
    from rollcam.firmware.rig import RigSpec

    try:
        return RigSpec.parse(text, "--rig")
    except ConfigError as exc:  # argparse shows a ValueError's text as the one-line error
        raise ValueError(str(exc).removeprefix("--rig: ")) from None


def _flag(name: str) -> str:
    return "--" + FLAG_NAMES.get(name, name.replace("_", "-"))


def _checked(parse: Callable[[str], Any]) -> Callable[[str], str]:
    """An argparse type that checks the text with ``parse`` and keeps the text (the option table reads it)."""

    def check(text: str) -> str:
        parse(text)
        return text

    check.__name__ = getattr(parse, "__name__", "value")
    return check


def add_camera_flags(p: argparse.ArgumentParser) -> None:
    """One flag per camera option of ``rollcam.firmware.options.OPTIONS`` (the emu: URI's options)."""
    from rollcam.firmware.options import OPTIONS, as_text

    scene = p.add_argument_group("scene (the emu: URI's scene options)")
    camera = p.add_argument_group("camera (the emu: URI's options)")
    for name, o in OPTIONS.items():
        group = scene if o.scenes is not None else camera
        default = "" if o.default is None else f" (default: {as_text(o.default)})"
        group.add_argument(_flag(name), dest=f"camera_{name}", default=None, metavar=name.upper(),
                           type=value_type(_checked(o.parse), _EXPECTED.get(o.parse, o.doc.split(": ", 1)[-1])),
                           help=o.doc + default)


def camera_options(args: argparse.Namespace) -> dict[str, str]:
    """The camera options given as flags, by option name (text, as in an emu: URI)."""
    return {k.removeprefix("camera_"): v for k, v in vars(args).items() if k.startswith("camera_") and v is not None}
