"""rollcam's emulated camera as a labgrid resource and driver, so a lab's labgrid environment file can declare one
and its tests capture from it, set its controls and run it under injected faults.

Registered through labgrid's public extension points (``target_factory.reg_resource``/``reg_driver``); an
environment file loads them with ``imports: [rollcam.host.integrations.labgrid]`` (docs/labs.md has an example):

- ``RollcamCamera`` (resource): ``source`` (a sensor name or an ``emu:`` URI), ``options`` (more ``emu:`` options:
  ``scene``, ``seed``, ``size``, ...), ``faults`` (a ``rollcam.common.faults`` plan, docs/faults.md) and
  ``transport``: ``emu`` (frames in process, exact) or ``http`` (the emulator's MJPEG server on 127.0.0.1, read back
  over HTTP as any client would; its ``url`` is what labgrid's own ``HTTPVideoStream`` takes). Validated when the
  environment loads: a bad sensor, option or plan is a ``ConfigError`` naming it.
- ``RollcamCameraDriver`` (driver, labgrid's ``VideoProtocol``): ``read()``/``frames(n)`` give rollcam ``Frame``s
  (pixels, row timing, ground truth), ``set_control``/``get_control``/``controls`` change the camera between frames,
  ``get_qualities()`` names the stream's GStreamer caps and ``stream()`` sends it through ``gst-launch-1.0`` (a
  window by default, as ``labgrid-client video`` shows a camera; any sink for a test).

labgrid (LGPL-2.1-or-later) comes with rollcam's ``labgrid`` extra; without it, importing this module raises the
one ``MissingDependencyError`` naming that extra.
"""

from __future__ import annotations

import subprocess
import urllib.parse
from fractions import Fraction
from typing import Any, ClassVar

import attr  # attrs: labgrid's own class toolkit (here already, through aiohttp)
from rollcam.common.errors import ConfigError, SourceError, require
from rollcam.emu.http.mjpeg import MjpegServer
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.spec import CameraSpec
from rollcam.sim.frame import Frame

from ..sources import CameraSource, open_camera
from ..sources.emu import device_spec

_FEATURE = "rollcam's labgrid resource and driver (rollcam.host.integrations.labgrid)"
_factory = require("labgrid.factory", "labgrid", "labgrid", _FEATURE)
_resource = require("labgrid.resource.common", "labgrid", "labgrid", _FEATURE)
_driver = require("labgrid.driver.common", "labgrid", "labgrid", _FEATURE)
_protocol = require("labgrid.protocol", "labgrid", "labgrid", _FEATURE)

TRANSPORTS = ("emu", "http")
"""How the driver reaches the camera: in process, or over the emulator's MJPEG server."""

GST_FORMATS = {"BGR3": ("BGR", 3), "RGB3": ("RGB", 3), "XR24": ("BGRx", 4), "GREY": ("GRAY8", 1),
               "YUYV": ("YUY2", 2), "UYVY": ("UYVY", 2)}
"""Packed V4L2 fourcc -> (GStreamer raw format, bytes per pixel): what ``stream()`` sends as ``video/x-raw``."""

DEFAULT_SINK = "videoconvert ! autovideosink"
"""Where ``stream()`` sends the video unless told: a window, as labgrid's own video drivers do."""


def frame_rate(spec: CameraSpec) -> Fraction:
    """The camera's exact frame rate (pixel clock over pixel clocks per frame), for GStreamer's caps."""
    timing = spec.settings.timing
    return Fraction(timing.pixel_rate_hz, timing.frame_period_pck)


@_factory.target_factory.reg_resource
@attr.s(eq=False)
class RollcamCamera(_resource.Resource):
    """An emulated rollcam camera: what it is (sensor, scene, options), its fault plan and how it is reached."""

    source = attr.ib(default="imx219", validator=attr.validators.instance_of(str))
    options = attr.ib(factory=dict, validator=attr.validators.instance_of(dict))
    faults = attr.ib(default="", validator=attr.validators.instance_of(str))
    transport = attr.ib(default="emu", validator=attr.validators.instance_of(str))

    def __attrs_post_init__(self) -> None:
        super().__attrs_post_init__()
        owner = f"labgrid resource RollcamCamera {self.name or ''}".rstrip()
        if self.transport not in TRANSPORTS:
            raise ConfigError(f"{owner}: transport {self.transport!r} is not one of {list(TRANSPORTS)}")
        self.spec, self.fault_plan = device_spec(self.uri, ConfigError)  # a bad sensor, option or plan fails now

    @property
    def uri(self) -> str:
        """The ``emu:`` URI of the camera: ``source`` with ``options`` and ``faults`` added to its query."""
        base = self.source if self.source.startswith("emu:") else f"emu:{self.source}"
        extra = {str(k): str(v).lower() if isinstance(v, bool) else str(v) for k, v in self.options.items()}
        if self.faults:
            extra["faults"] = self.faults
        if not extra:
            return base
        return base + ("&" if "?" in base else "?") + urllib.parse.urlencode(extra, safe=",=@")


@_factory.target_factory.reg_driver
@attr.s(eq=False)
class RollcamCameraDriver(_driver.Driver, _protocol.VideoProtocol):
    """Frames, controls and a GStreamer stream of a ``RollcamCamera``; the camera runs while the driver is active."""

    bindings: ClassVar[dict[str, str]] = {"camera": "RollcamCamera"}

    def __attrs_post_init__(self) -> None:
        super().__attrs_post_init__()
        self.device: FirmwareCamera | None = None
        self.server: MjpegServer | None = None
        self.source: CameraSource | None = None

    def on_activate(self) -> None:
        """Start the camera (and for ``transport: http`` its MJPEG server) and open the stream."""
        res = self.camera
        if res.transport == "emu":
            self.source = open_camera(res.uri)
            self.device = self.source.device
            return
        self.device = FirmwareCamera(res.spec)
        self.server = MjpegServer(self.device, "127.0.0.1", 0, faults=res.fault_plan)
        self.server.start()
        self.source = open_camera(self.server.url)

    def on_deactivate(self) -> None:
        """Close the stream and stop the server."""
        for part in (self.source, self.server):
            if part is not None:
                part.close()
        self.source = self.server = self.device = None

    @property
    def url(self) -> str | None:
        """The MJPEG stream's URL (``transport: http``), else None."""
        return None if self.server is None else self.server.url

    @property
    def fault_stats(self) -> Any:
        """What the camera's fault plan injected so far (``rollcam.common.faults.FaultStats``), or None when idle."""
        part = self.server if self.server is not None else self.source
        return None if part is None else part.fault_stats

    @_driver.Driver.check_active
    def read(self) -> Frame:
        """The camera's next frame."""
        frame = self.source.read()
        if frame is None:
            raise SourceError(f"{self.camera.uri}: the stream ended")
        return frame

    def frames(self, count: int) -> list[Frame]:
        """The camera's next ``count`` frames."""
        return [self.read() for _ in range(count)]

    @_driver.Driver.check_active
    def info(self) -> dict[str, Any]:
        """Sensor, size, timing and scene of the stream, as ``rollcam capture --info`` reports them."""
        return self.source.info()

    @_driver.Driver.check_active
    def controls(self) -> dict[str, dict[str, Any]]:
        """Every control of the camera with its range and current value."""
        return self.device.controls()

    @_driver.Driver.check_active
    def get_control(self, name: str) -> int:
        """A control's current value."""
        return self.device.get_control(name)

    @_driver.Driver.check_active
    def set_control(self, name: str, value: int) -> int:
        """Set a control (clamped to its range) from the next frame on; returns the value in effect."""
        return self.device.set_control(name, value)

    def caps(self) -> str:
        """The GStreamer caps of the camera's stream."""
        spec = self.camera.spec if self.device is None else self.device.spec
        s = spec.settings
        rate = frame_rate(spec)
        if self.camera.transport == "http" or spec.output_format == "MJPG":
            kind = "image/jpeg"
        elif spec.output_format in GST_FORMATS:
            kind = f"video/x-raw,format={GST_FORMATS[spec.output_format][0]}"
        else:
            kind = f"video/x-bayer,fourcc={spec.output_format}"
        return f"{kind},width={s.width},height={s.height},framerate={rate.numerator}/{rate.denominator}"

    def get_qualities(self) -> tuple[str, list[tuple[str, str]]]:
        """labgrid's VideoProtocol: one quality, ``native``, the camera's own format, size and frame rate."""
        return "native", [("native", self.caps())]

    @_driver.Driver.check_active
    def stream(self, quality_hint: str | None = None, controls: str | None = None, *, sink: str = DEFAULT_SINK,
               frames: int | None = None, timeout_s: float | None = None) -> int:
        """labgrid's VideoProtocol: send the stream through ``gst-launch-1.0 fdsrc ! rawvideoparse ! SINK`` until
        ``frames`` were sent or GStreamer stops; returns its exit status. ``controls`` is labgrid's
        ``name=value,...`` text, set before the first frame; ``sink`` any GStreamer sink pipeline."""
        if quality_hint not in (None, "native"):
            raise ConfigError(f"{self.camera.uri}: unknown video quality {quality_hint!r}; this camera has 'native'")
        for item in filter(None, (controls or "").split(",")):
            name, sep, value = item.partition("=")
            if not sep or not value.strip().lstrip("-").isdigit():
                raise ConfigError(f"{self.camera.uri}: control {item!r} is not NAME=INTEGER")
            self.set_control(name.strip(), int(value))
        fmt = self.camera.spec.output_format
        if self.camera.transport != "emu" or fmt not in GST_FORMATS:
            raise ConfigError(f"{self.camera.uri}: stream() sends packed raw video in process ({sorted(GST_FORMATS)}); "
                              f"this camera gives {fmt!r} over {self.camera.transport!r}")
        gst_format, depth = GST_FORMATS[fmt]
        s = self.device.spec.settings
        rate = frame_rate(self.device.spec)
        parse = (f"fdsrc fd=0 blocksize={s.width * s.height * depth} ! rawvideoparse format={gst_format.lower()} "
                 f"width={s.width} height={s.height} framerate={rate.numerator}/{rate.denominator} "
                 f"plane-strides=<{s.width * depth}>")
        argv = ["gst-launch-1.0", "-q", *parse.split(), "!", *sink.split()]
        with subprocess.Popen(argv, stdin=subprocess.PIPE) as gst:
            sent = 0
            try:
                while frames is None or sent < frames:
                    gst.stdin.write(self.read().data.tobytes())
                    sent += 1
                gst.stdin.close()
            except BrokenPipeError:  # GStreamer stopped (a window closed, an error): its status says which
                pass
            return gst.wait(timeout_s)


__all__ = ["DEFAULT_SINK", "GST_FORMATS", "TRANSPORTS", "RollcamCamera", "RollcamCameraDriver", "frame_rate"]
