"""``rollcam emulate SENSOR``: serve an emulated camera to other programs until Ctrl-C.

One FirmwareCamera (``rollcam.firmware``) is streamed in real time by one FramePump and offered on every
transport asked for: ``--http HOST:PORT`` (MJPEG for ``cv2.VideoCapture``, browsers, ffmpeg) and
``--serial`` (the control protocol on a pseudo-terminal) and ``--usbip HOST:PORT`` (a UVC camera that
``usbip attach`` or rollcam's USB/IP client imports; the UVC host's commit programs the camera's mode and
frame rate, as on a real device). With no transport option, HTTP on 127.0.0.1:8080. A transport is one
entry of ``TRANSPORTS``: its option and a starter that returns the running server (something with
``close()``) and the lines telling a user where to connect.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import signal
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

LOOPBACK = ("127.0.0.1", "localhost", "::1")
DEFAULT_HTTP = "127.0.0.1:8080"


def host_port(text: str) -> tuple[str, int]:
    """``HOST:PORT``, ``:PORT`` or ``PORT`` -> (host, port) for argparse; the host defaults to 127.0.0.1."""
    from rollcam.common.errors import ConfigError

    from .sources.base import parse_host_port

    try:
        return parse_host_port(text)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


@dataclass
class Running:
    """A started transport: the object to close and the lines that say where to connect."""

    name: str
    server: Any
    lines: list[str]
    info: dict[str, Any]
    uses_pump: bool = True


def _warn_if_wide(name: str, host: str) -> None:
    if host not in LOOPBACK:
        print(f"rollcam: warning: {name} bound to {host!r}, reachable from other machines; it has no "
              "authentication", file=sys.stderr)


def start_http(args: argparse.Namespace, camera: Any, pump: Any) -> Running | None:
    """The MJPEG-over-HTTP server, when ``--http`` is given (or no transport at all)."""
    if args.http is None:
        return None
    from rollcam.emu.http_mjpeg import MjpegServer

    host, port = args.http
    _warn_if_wide("HTTP", host)
    try:
        server = MjpegServer(camera, host, port, pump=pump, quality=args.quality)
    except OSError as exc:
        raise OSError(f"cannot serve HTTP on {host}:{port}: {exc.strerror or exc}") from None
    server.start()
    url = server.url
    base = url.rsplit("/", 1)[0]
    return Running("http", server, [f"MJPEG stream:  {url}   (cv2.VideoCapture({url!r}))",
                                    f"snapshot:      {base}/snapshot.jpg", f"status:        {base}/status.json"],
                   {"url": url})


def start_serial(args: argparse.Namespace, camera: Any, pump: Any) -> Running | None:
    """The control protocol on a pseudo-terminal, when ``--serial`` is given."""
    if not args.serial:
        return None
    from rollcam.emu.serial_pty import PtySerialServer

    server = PtySerialServer(camera)
    server.start()
    return Running("serial", server, [f"serial port:   {server.path}   (serial.Serial({server.path!r}); "
                                      "send '*IDN?' or 'HELP')"], {"path": server.path})


def start_usbip(args: argparse.Namespace, camera: Any, pump: Any) -> Running | None:
    """The camera as a UVC device on a USB/IP server, when ``--usbip`` is given."""
    if args.usbip is None:
        return None
    from rollcam.emu.usbip.server import USBIPServer, usbip_commands
    from rollcam.emu.uvc import DeviceIdentity, FirmwareProducer, UVCFunction

    host, port = args.usbip
    _warn_if_wide("USB/IP", host)
    function = UVCFunction(FirmwareProducer(camera), transfer=args.usb_transfer, realtime=True,
                           identity=DeviceIdentity(serial=camera.serial_number))
    try:
        server = USBIPServer([function], host, port)
    except OSError as exc:
        function.close()
        raise OSError(f"cannot serve USB/IP on {host}:{port}: {exc.strerror or exc}") from None
    addr_host, addr_port = server.address
    busids = sorted(server.exports)
    list_cmd, attach_cmd = usbip_commands(addr_host, addr_port, busids[0])
    return Running("usbip", server, [f"USB/IP:        {addr_host}:{addr_port} busid {', '.join(busids)}   "
                                     f"({list_cmd}; {attach_cmd})"],
                   {"host": addr_host, "port": addr_port, "busids": busids}, uses_pump=False)


def _http_option(g: argparse._ArgumentGroup) -> None:
    g.add_argument("--http", type=host_port, default=None, metavar="HOST:PORT",
                   help=f"serve MJPEG over HTTP (default when no transport is given: {DEFAULT_HTTP})")
    g.add_argument("--quality", type=int, default=85, help="JPEG quality for HTTP (default: 85)")


def _serial_option(g: argparse._ArgumentGroup) -> None:
    g.add_argument("--serial", action="store_true", help="serve the control protocol on a pseudo-terminal")


def _usbip_option(g: argparse._ArgumentGroup) -> None:
    g.add_argument("--usbip", type=host_port, default=None, metavar="HOST:PORT",
                   help="serve the camera as a UVC device over USB/IP (the usbip protocol port is 3240)")
    g.add_argument("--usb-transfer", choices=("iso", "bulk"), default="iso",
                   help="UVC streaming endpoint type for --usbip (default: iso)")


Starter = Callable[[argparse.Namespace, Any, Any], "Running | None"]
TRANSPORTS: list[tuple[str, Callable[[argparse._ArgumentGroup], None], Starter]] = [
    ("http", _http_option, start_http),
    ("serial", _serial_option, start_serial),
    ("usbip", _usbip_option, start_usbip),
]
"""Transports in start order: (name = the option's dest, add its options, starter). A starter gets the parsed
arguments, the FirmwareCamera and the shared FramePump, and returns None when its option was not given. A new
transport (``--usbip HOST:PORT``) is one entry here."""


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``emulate`` command."""
    p = sub.add_parser("emulate", help="serve an emulated camera over HTTP (MJPEG), a serial pty and USB/IP (UVC)",
                       description="Stream an emulated sensor in real time and serve it until Ctrl-C: MJPEG over "
                                   "HTTP (--http, default 127.0.0.1:8080), the serial control protocol on a "
                                   "pseudo-terminal (--serial) and a UVC camera over USB/IP (--usbip).",
                       epilog="Example: rollcam emulate imx219 --scene street --speed fast --http 127.0.0.1:8080 "
                              "--serial")
    p.add_argument("sensor", metavar="SENSOR", help="sensor name (see 'rollcam list') or a .yaml path")
    _camera_flags(p)
    g = p.add_argument_group("transports")
    for _name, add_options, _start in TRANSPORTS:
        add_options(g)
    p.add_argument("--duration", type=float, default=None, metavar="SECONDS", help="stop after this long")
    p.add_argument("--json", action="store_true", help="print the endpoints as one JSON line")
    p.set_defaults(func=cmd_emulate)


FLAG_NAMES = {"serial": "serial-number"}
"""Camera options whose flag is not ``--<name>`` (``--serial`` is the serial transport)."""


def _flag(name: str) -> str:
    return "--" + FLAG_NAMES.get(name, name.replace("_", "-"))


def _camera_flags(p: argparse.ArgumentParser) -> None:
    """One flag per camera option of ``rollcam.firmware.options.OPTIONS`` (the emu: URI's options), taken as
    text and parsed by the option table, so a value means and is checked the same as in an emu: URI."""
    from rollcam.firmware.options import OPTIONS, as_text

    scene = p.add_argument_group("scene (the emu: URI's scene options)")
    camera = p.add_argument_group("camera (the emu: URI's options)")
    for name, o in OPTIONS.items():
        group = scene if o.scenes is not None else camera
        default = "" if o.default is None else f" (default: {as_text(o.default)})"
        group.add_argument(_flag(name), dest=f"camera_{name}", default=None, metavar=name.upper(),
                           help=o.doc + default)


def camera_options(args: argparse.Namespace) -> dict[str, str]:
    """The camera options given as flags, by option name."""
    return {k.removeprefix("camera_"): v for k, v in vars(args).items() if k.startswith("camera_") and v is not None}


def wait_until_stopped(stop: threading.Event, duration_s: float | None, pump: Any, poll_s: float = 0.5) -> None:
    """Wait for ``stop`` or ``duration_s``, looking every ``poll_s`` whether the frame pump is still alive: a
    pump that died raises its error (a DeviceError) here, so ``emulate`` ends with it instead of serving
    silence."""
    from rollcam.common.lifecycle import Deadline

    deadline = Deadline(duration_s)
    while not stop.wait(deadline.within(poll_s)):
        pump.check()
        if deadline.expired:
            return
    pump.check()


def cmd_emulate(args: argparse.Namespace) -> int:
    """Run the emulator until Ctrl-C, SIGTERM or ``--duration``; every transport is closed on the way out."""
    from rollcam.emu.pump import FramePump
    from rollcam.firmware.camera import FirmwareCamera
    from rollcam.firmware.spec import CameraSpec

    if not any(getattr(args, name, None) for name, _add, _start in TRANSPORTS):
        args.http = host_port(DEFAULT_HTTP)
    camera = FirmwareCamera(CameraSpec.from_options(args.sensor, camera_options(args), "rollcam emulate"))
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    running: list[Running] = []
    pump = FramePump(camera, bands=1, name="rollcam-emulate")
    try:
        for _name, _add, starter in TRANSPORTS:
            started = starter(args, camera, pump)
            if started is not None:
                running.append(started)
        camera.stream_on()
        if any(r.uses_pump for r in running):  # UVC paces its own frames; do not render for nobody
            pump.start()
        if args.json:
            print(json.dumps({"sensor": camera.sensor.name, "identity": camera.identity(),
                              **{r.name: r.info for r in running}}), flush=True)
        else:
            print(f"emulating {camera!r}", flush=True)
            for r in running:
                for line in r.lines:
                    print(f"  {line}", flush=True)
            print("press Ctrl-C to stop", flush=True)
        with contextlib.suppress(KeyboardInterrupt):  # Ctrl-C is the normal way to stop a server
            wait_until_stopped(stop, args.duration, pump)
    finally:
        pump.close()
        for r in reversed(running):
            r.server.close()
        camera.stream_off()
        signal.signal(signal.SIGTERM, previous)
    print(f"stopped; {camera.stats.frames} frames made, {camera.stats.skipped} skipped", file=sys.stderr)
    return 0
