"""``rollcam emulate SENSOR``: serve an emulated camera to other programs until Ctrl-C.

One FirmwareCamera (``rollcam.firmware``) is streamed in real time by one FramePump and offered on every
transport asked for: ``--http HOST:PORT`` (MJPEG for ``cv2.VideoCapture``, browsers, ffmpeg) and
``--serial`` (the control protocol on a pseudo-terminal) and ``--usbip HOST:PORT`` (a UVC camera that
``usbip attach`` or rollcam's USB/IP client imports; the UVC host's commit programs the camera's mode and
frame rate, as on a real device). With no transport option, HTTP on 127.0.0.1:8080. A transport is one
entry of ``TRANSPORTS``: a starter that returns the running server (something with ``close()``) and the
lines telling a user where to connect; its flags are in ``rollcam.host.commands.emulate``, the command line.
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


@dataclass
class Running:
    """A started transport: the object to close and the lines that say where to connect."""

    name: str
    server: Any
    lines: list[str]
    info: dict[str, Any]
    uses_pump: bool = True
    injector: Any = None
    """What holds the transport's ``fault_stats`` (or its ``exports``) when ``server`` is a wrapper."""


def _warn_if_wide(name: str, host: str, what: str = "it has no authentication") -> None:
    if host not in LOOPBACK:
        print(f"rollcam: warning: {name} bound to {host!r}, reachable from other machines; {what}", file=sys.stderr)


def start_http(args: argparse.Namespace, camera: Any, pump: Any) -> Running | None:
    """The MJPEG-over-HTTP server and its live page, when ``--http`` is given (or no transport at all)."""
    if args.http is None:
        return None
    from rollcam.emu.http.mjpeg import MjpegServer, images_sent
    from rollcam.emu.http.view import LiveView
    from rollcam.emu.http.view_controls import CameraControls

    host, port = args.http
    _warn_if_wide("HTTP", host, "the MJPEG stream has no authentication; the live view needs the token below")
    stack = contextlib.ExitStack()  # closed last-in first: the view, then the server, then the detector
    annotate = None
    if getattr(args, "detector", None):
        from ..detectors import load_detector
        from .view import detector_annotator

        detector = load_detector(args.detector)
        stack.callback(detector.close)
        annotate = detector_annotator(detector)
    try:
        server = MjpegServer(camera, host, port, pump=pump, quality=args.quality, faults=args.faults)
    except OSError as exc:
        stack.close()
        raise OSError(f"cannot serve HTTP on {host}:{port}: {exc.strerror or exc}") from None
    stack.callback(server.close)
    info = {"sensor": camera.sensor.name, "uri": "rollcam emulate"}
    view = LiveView(server, CameraControls(camera), annotate=annotate, info=lambda: info)
    stack.callback(view.close)
    try:
        server.start()
    except BaseException:
        stack.close()
        raise
    url = server.url
    base = url.rsplit("/", 1)[0]
    auth = "   (token required: bound beyond loopback)" if view.token else ""
    if images_sent(camera):
        lines = [f"MJPEG stream:  {url}   (cv2.VideoCapture({url!r}))", f"snapshot:      {base}/snapshot.jpg"]
    else:
        lines = [f"in-sensor:     {base}/insensor.jsonl   (metadata only: no image leaves the sensor)"]
    return Running("http", stack, [f"live view:     {view.url}{auth}", *lines, f"status:        {base}/status.json"],
                   {"url": url, "view": view.url, "token": view.token}, injector=server)


def start_serial(args: argparse.Namespace, camera: Any, pump: Any) -> Running | None:
    """The control protocol on a pseudo-terminal, when ``--serial`` is given."""
    if not args.serial:
        return None
    from rollcam.emu.serial_pty import PtySerialServer

    server = PtySerialServer(camera, faults=args.faults)
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
    ids = {} if args.usb_id is None else dict(zip(("vendor_id", "product_id"), args.usb_id, strict=True))
    function = UVCFunction(FirmwareProducer(camera), transfer=args.usb_transfer, realtime=True,
                           identity=DeviceIdentity(serial=camera.serial_number, **ids), faults=args.faults)
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


def start_gadget(args: argparse.Namespace, camera: Any, pump: Any) -> Running | None:
    """The camera as a USB webcam through Linux's UVC gadget function (``rollcam gadget``)."""
    from rollcam.emu.gadget import GadgetServer
    from rollcam.emu.uvc import DeviceIdentity, FirmwareProducer

    ids = {} if args.usb_id is None else dict(zip(("vendor_id", "product_id"), args.usb_id, strict=True))
    server = GadgetServer(FirmwareProducer(camera), udc=args.udc, identity=DeviceIdentity(
        serial=camera.serial_number, **ids), frame_log=args.frame_log).start()
    ident = DeviceIdentity(**ids)
    return Running("gadget", server, [f"USB gadget:    UVC camera {ident.vendor_id:04x}:{ident.product_id:04x} on "
                                      f"{server.udc} (node {server.node})"],
                   {"udc": server.udc, "node": server.node, "usb_id": f"{ident.vendor_id:04x}:{ident.product_id:04x}"},
                   uses_pump=False)


Starter = Callable[[argparse.Namespace, Any, Any], "Running | None"]
TRANSPORTS: list[tuple[str, Starter]] = [("http", start_http), ("serial", start_serial), ("usbip", start_usbip)]
"""Transports in start order: (name = the option's dest, starter). A starter gets the parsed arguments, the
FirmwareCamera and the shared FramePump, and returns None when its option was not given. A new transport is
one entry here and its flags in ``rollcam.host.commands.emulate``."""
GADGET_TRANSPORTS: list[tuple[str, Starter]] = [("gadget", start_gadget), ("http", start_http),
                                                ("serial", start_serial)]
"""``rollcam gadget``'s: the UVC gadget first (a board without one fails before any door opens), then the doors."""


def wait_until_stopped(stop: threading.Event, duration_s: float | None, pump: Any, poll_s: float = 0.5,
                       servers: tuple = ()) -> None:
    """Wait for ``stop`` or ``duration_s``, looking every ``poll_s`` whether the frame pump (and each of
    ``servers`` that has a ``check()``) is still alive: one that died raises its error (a DeviceError) here, so
    ``emulate`` ends with it instead of serving silence."""
    from rollcam.common.lifecycle import Deadline

    checks = [pump.check, *(s.check for s in servers if hasattr(s, "check"))]
    deadline = Deadline(duration_s)
    while not stop.wait(deadline.within(poll_s)):
        for check in checks:
            check()
        if deadline.expired:
            return
    for check in checks:
        check()


def _fault_stats(server: Any) -> str:
    """``kind=count`` of the faults a transport injected (the USB/IP server's are its functions')."""
    holders = [e.function for e in server.exports.values()] if hasattr(server, "exports") else [server]
    totals: dict[str, int] = {}
    for h in holders:
        for k, v in h.fault_stats.to_json().items():
            totals[k] = totals.get(k, 0) + v
    return ", ".join(f"{k}={v}" for k, v in totals.items() if v)


def ledger_line(camera: Any) -> str:
    """The stream's ledger on one line: bytes per frame sent, link utilisation, energy per frame of the pipelines."""
    doc = camera.insensor.ledger(camera.spec).to_json()
    sent, e = doc["rows"]["sent"], doc["energy_uj_per_frame"]
    util = "no link in the hw_config" if sent["utilisation"] is None else \
        f"{100 * sent['utilisation']:.3f}% of the {doc['link']['bus']} link"
    pipes = "" if doc["mode"] == "none" else \
        f", energy/frame in-sensor {e['insensor']:.1f} uJ vs host {e['host']:.1f} uJ"
    return f"{sent['bytes_per_frame']:,} B/frame sent ({doc['mode']}), {sent['mbit_s']:.2f} Mbit/s, {util}{pipes}"


def for_camera(args: argparse.Namespace, index: int) -> argparse.Namespace:
    """The arguments of a rig's camera ``index``: each transport's port moved up by ``index`` (port 0, a free
    port, stays 0), so camera 0 serves where a lone camera would and the others on the next ports."""
    if index == 0:
        return args
    moved = argparse.Namespace(**vars(args))
    for name in ("http", "usbip"):
        value = getattr(args, name, None)
        if value is not None and value[1] != 0:
            setattr(moved, name, (value[0], value[1] + index))
    return moved


class _Watch:
    """Everything ``wait_until_stopped`` checks for a failure: each camera's pump and the rig's trigger line."""

    def __init__(self, *parts: Any) -> None:
        self.parts = parts

    def check(self) -> None:
        for part in self.parts:
            part.check()


def serve(args: argparse.Namespace, camera_options: dict[str, str],
          transports: list[tuple[str, Starter]] | None = None, command: str = "rollcam emulate") -> int:
    """Run the emulator of ``args.sensor`` programmed by ``camera_options`` (text, as in an emu: URI) on the
    ``transports`` (default ``TRANSPORTS``) that ``args`` asks for, until Ctrl-C, SIGTERM or ``args.duration``
    (0: stop at once); every transport is closed on the way out. With ``args.rig`` (a ``RigSpec``), every
    camera of the rig is served, camera ``i`` on each transport's port plus ``i`` (``for_camera``)."""
    from rollcam.emu.pump import FramePump
    from rollcam.firmware.camera import FirmwareCamera
    from rollcam.firmware.rig import LiveRig
    from rollcam.firmware.spec import CameraSpec

    spec = CameraSpec.from_options(args.sensor, camera_options, command)
    rig_spec = getattr(args, "rig", None)
    rig = None if rig_spec is None else LiveRig(rig_spec, spec)
    cameras = [FirmwareCamera(spec)] if rig is None else rig.cameras
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    running: list[list[Running]] = []
    pumps: list[Any] = []
    try:
        for index, camera in enumerate(cameras):
            pump = FramePump(camera, bands=1, name="rollcam-emulate" + (f"-{index}" if rig else ""))
            pumps.append(pump)
            running.append([])
            for _name, starter in TRANSPORTS if transports is None else transports:
                started = starter(for_camera(args, index), camera, pump)
                if started is not None:
                    running[-1].append(started)
        if rig is None:
            cameras[0].stream_on()
        else:
            rig.start()
        for pump, started_here in zip(pumps, running, strict=True):
            if any(r.uses_pump for r in started_here):  # UVC paces its own frames; do not render for nobody
                pump.start()
        _announce(args, cameras, running, rig_spec, None if rig is None else rig.world0)
        with contextlib.suppress(KeyboardInterrupt):  # Ctrl-C is the normal way to stop a server
            wait_until_stopped(stop, args.duration, _Watch(*pumps, *([] if rig is None else [rig])),
                               servers=tuple(r.server for started in running for r in started))
    finally:
        for pump in pumps:
            pump.close()
        for started_here in reversed(running):
            for r in reversed(started_here):
                r.server.close()
        if rig is None:
            cameras[0].stream_off()
        else:
            rig.close()
        signal.signal(signal.SIGTERM, previous)
    for index, (camera, pump, started_here) in enumerate(zip(cameras, pumps, running, strict=True)):
        _report(args, camera, pump, started_here, f"camera {index}: " if rig else "")
    return 0


def _announce(args: argparse.Namespace, cameras: list[Any], running: list[list[Running]], rig: Any,
              world0_ns: int | None = None) -> None:
    """The endpoints, on stdout: one JSON line (``--json``; a rig's is ``{"rig": ..., "cameras": [...]}``, the
    rig's with ``world_start_monotonic_ns``: the host's CLOCK_MONOTONIC at the rig's world time 0) or lines for
    a person."""
    def doc(camera: Any, started: list[Running]) -> dict[str, Any]:
        return {"sensor": camera.sensor.name, "identity": camera.identity(), "faults": args.faults.to_text(),
                "ledger": camera.insensor.ledger(camera.spec).to_json(), **{r.name: r.info for r in started}}

    if args.json:
        if rig is None:
            print(json.dumps(doc(cameras[0], running[0])), flush=True)
        else:
            docs = [doc(c, r) for c, r in zip(cameras, running, strict=True)]
            print(json.dumps({"rig": {**rig.to_json(), "world_start_monotonic_ns": world0_ns}, "cameras": docs}),
                  flush=True)
        return
    if rig is not None:
        print(f"emulating a rig: {rig.to_text()}", flush=True)
    for index, (camera, started) in enumerate(zip(cameras, running, strict=True)):
        name = "" if rig is None else f"camera {index} "
        print(f"emulating {name}{camera!r}" + (f" with faults {args.faults}" if args.faults else ""), flush=True)
        for r in started:
            for line in r.lines:
                print(f"  {line}", flush=True)
        print(f"  ledger:        {ledger_line(camera)}", flush=True)
    print("press Ctrl-C to stop", flush=True)


def _report(args: argparse.Namespace, camera: Any, pump: Any, running: list[Running], name: str) -> None:
    """What one camera did, on stderr, once stopped."""
    st = camera.stats
    extra = "" if camera.spec.insensor is None else \
        f"; in-sensor network ran on {st.insensor_runs}, skipped {st.insensor_skipped} (accelerator busy)"
    ps = pump.stats  # camera.stats.frames also counts frames the pump made ahead and threw away
    paced = f" ({ps.frames} delivered by the pump, {ps.remade} remade after a control change)" \
        if ps.frames or ps.remade else ""
    print(f"{name}stopped; {st.frames} frames made{paced}, {st.skipped} skipped{extra}", file=sys.stderr)
    print(f"{name}ledger: {ledger_line(camera)}", file=sys.stderr)
    for r in running if args.faults else ():  # a transport that injects nothing (the gadget) has no stats
        stats = _fault_stats(r.injector if r.injector is not None else r.server)
        if stats:
            print(f"{name}faults injected on {r.name}: {stats}", file=sys.stderr)
