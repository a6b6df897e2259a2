"""``emu:SENSOR?scene=..&seed=..`` -- an emulated sensor rendering a synthetic scene in process.

The options are the emulated camera's option table (``rollcam.firmware.options``, the same one ``rollcam
emulate`` flags, ``rollcam://`` URLs and the serial ``OPT``/``SCENE`` commands read): ``scene``, ``seed``,
``camera``, the scene kind's own (``time``, ``speed``, ``pedestrians``, ``ego``; ``vx``; ``level``), ``size``,
``fps``, ``shutter``, ``readout``, ``exposure_us``, ``gain`` (linear total), ``format``, ``physics``,
``blur_px``, ``noise``, the lens's and the ISP's (``vignette``, ``lens_blur_px``, ``defocus_px``, ``sharpen``,
``jpeg_quality``: docs/optics.md), ``serial``, ``noise_seed``, ``hflip``, ``vflip``, ``test_pattern``, the IMU's and the
in-sensor network's (``insensor=personnet-raw``: frames carry its results, docs/insensor.md). Five more belong to
the source: ``start_ns`` (device clock at frame 0), ``frames`` (stop after N frames; endless by default) and
``rig``/``rig_cam`` (camera ``rig_cam`` of a multi-camera rig, ``rollcam.firmware.rig``: docs/rigs.md) and
``faults`` (a ``rollcam.common.faults`` plan, e.g. ``faults=drop=5,error=2,seed=3``; in process ``drop`` skips
frames (a gap in ``sequence``), ``error`` sets ``meta["error"]``, ``disconnect=N`` makes the read after N
frames raise ``SourceError``, ``seqwrap``/``tswrap`` shift ``sequence``/``timestamp_ns``, the frame-counter
faults rewrite, freeze or skip ``sequence``, ``grey``/``black``/``frozen`` replace the image (``meta["image_fault"]``
names it) and ``regreset`` returns the device's controls to those it was made with; every device a
``rollcam run`` or ``rollcam emulate`` makes from the URI takes the same plan, see docs/faults.md).

Frames come from a ``FirmwareCamera`` holding the ``CameraSpec`` the options build, the same device object the
V4L2, serial, HTTP and UVC paths stream, read without pacing: frame ``n`` is the one the device schedules at
``start_ns + frame_start(n)``. Example: ``emu:imx219?format=pRAA&scene=flat&level=0.3&gain=2``.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from rollcam.common.errors import ConfigError, SourceError
from rollcam.common.faults import FaultInjector, FaultPlan
from rollcam.common.values import bounded, convert_option, non_negative_int, positive_int
from rollcam.firmware.camera import FirmwareCamera, FramePlan
from rollcam.firmware.imaging import encode
from rollcam.firmware.labfaults import FrameFaults
from rollcam.firmware.options import MAX_DEVICE_NS, OPTIONS
from rollcam.firmware.rig import Rig, RigSpec
from rollcam.firmware.spec import CameraSpec
from rollcam.sim.frame import Frame
from rollcam.sim.synthetic import SyntheticCamera

from .base import CameraSource, SourceURI

SOURCE_OPTIONS = {"start_ns", "frames", "faults", "rig", "rig_cam"}
"""Options of the source itself; all others are the camera's (``rollcam.firmware.options.OPTIONS``)."""


def build_device(sensor_name: str, opts: SourceURI) -> tuple[FirmwareCamera, int]:
    """The device an ``emu:`` URI describes, and its ``start_ns``."""
    owner = f"source {opts.uri!r}"
    opts.take(set(), set(OPTIONS) | SOURCE_OPTIONS)
    camera_opts = {k: v for k, v in opts.options.items() if k not in SOURCE_OPTIONS}
    spec = CameraSpec.from_options(sensor_name, camera_opts, owner, SourceError)
    start_ns = opts.get("start_ns", bounded(non_negative_int, 0, MAX_DEVICE_NS), 0)
    return FirmwareCamera(spec, clock=lambda: 0), start_ns


def rig_choice(options: dict[str, str], owner: str, error: type[Exception] = SourceError
               ) -> tuple[RigSpec, int] | None:
    """The ``rig=`` declaration of a URI's options and the camera ``rig_cam=`` picks (default 0); None without
    ``rig=``. Bad text raises ``error`` naming ``owner``."""
    text = options.get("rig")
    if text is None:
        if "rig_cam" in options:
            raise error(f"{owner}: rig_cam= needs rig=, e.g. rig=stereo,baseline=0.12&rig_cam=1")
        return None
    try:
        rig = RigSpec.parse(text, owner)
        index = non_negative_int(options.get("rig_cam", "0"))
    except ConfigError as exc:
        raise error(str(exc)) from None
    except ValueError as exc:
        raise error(f"{owner}: rig_cam={options['rig_cam']!r} is invalid ({exc})") from None
    if index >= rig.n:
        raise error(f"{owner}: rig_cam={index} is not a camera of the {rig.n}-camera rig (0..{rig.n - 1})")
    return rig, index


def build_rig(device: FirmwareCamera, start_ns: int, opts: SourceURI) -> tuple[Rig, int] | None:
    """The rig of an ``emu:`` URI's ``rig=`` option (``rollcam.firmware.rig``) and the camera ``rig_cam=`` picks
    (default 0), with world time ``start_ns`` at its frame 0; None without ``rig=``."""
    choice = rig_choice(opts.options, f"source {opts.uri!r}")
    if choice is None:
        return None
    try:
        return Rig(choice[0], device.spec, start_ns), choice[1]
    except ConfigError as exc:
        raise SourceError(f"source {opts.uri!r}: {exc}") from None


def fault_plan(opts: SourceURI) -> FaultPlan:
    """The ``faults=`` plan of an ``emu:`` URI (no fault when absent)."""
    return opts.get("faults", lambda text: FaultPlan.parse(text, f"source {opts.uri!r}"), FaultPlan())


def device_spec(source: str, error: type[Exception] = SourceError) -> tuple[CameraSpec, FaultPlan]:
    """The spec and ``faults=`` plan of a device described by a sensor name or an ``emu:`` URI, for the doors that
    build a device of their own from one (``rollcam run``'s /dev/videoN, the picamera2 stand-in); ``error`` is
    what a bad source raises. The in-process source's own options (``start_ns``, ``frames``) are refused, and so
    is ``rig=`` (``rig_device_spec`` is for the doors that build a rig's cameras)."""
    spec, plan, choice = rig_device_spec(source, error)
    if choice is not None:
        raise error(f"source {source!r}: rig= is for emu: sources, rollcam emulate --rig and rollcam run devices")
    return spec, plan


def rig_device_spec(source: str, error: type[Exception] = SourceError
                    ) -> tuple[CameraSpec, FaultPlan, tuple[RigSpec, int] | None]:
    """``device_spec``'s spec and plan, and the URI's ``rig=``/``rig_cam=`` choice (None without ``rig=``): the
    spec is the rig's common one, before the camera is placed (``rollcam.firmware.rig.placed``)."""
    from . import parse_uri

    uri = parse_uri(source if source.startswith("emu:") else f"emu:{source}")
    owner = f"source {source!r}"
    if uri.scheme != "emu" or not uri.target:
        raise error(f"{owner}: name a sensor or an emu: URI, e.g. emu:imx219?size=640x480")
    choice = rig_choice(uri.options, owner, error)
    camera_opts = {k: v for k, v in uri.options.items() if k not in ("faults", "rig", "rig_cam")}
    plan = convert_option(uri.options, "faults", lambda text: FaultPlan.parse(text, owner), FaultPlan(), owner, error)
    return CameraSpec.from_options(uri.target, camera_opts, owner, error), plan, choice


class EmuSource(CameraSource):
    """Frames from a FirmwareCamera, in sequence, with exact timing and ground truth."""

    supports_pairs = True

    def __init__(self, uri: SourceURI) -> None:
        self.uri = uri.uri
        self.device, self.start_ns = build_device(uri.target, uri)
        self.rig = build_rig(self.device, self.start_ns, uri)
        if self.rig is not None:
            self.device = self.rig[0].cameras[self.rig[1]]
        self.limit = uri.get("frames", positive_int)
        self.faults = FaultInjector(fault_plan(uri))
        self.fault_stats = self.faults.stats
        self.frame_faults = FrameFaults(self.faults, self.device)
        self.index = 0
        self.delivered = 0
        self._schedule = self.device.schedule(self.start_ns)

    @property
    def camera(self) -> SyntheticCamera:
        """The SyntheticCamera behind the device (renderer, line times, settings)."""
        return self.device.synthetic

    @property
    def spec(self) -> CameraSpec:
        """The camera's validated description."""
        return self.device.spec

    def _next(self, shutters: tuple[str | None, ...]) -> list[Frame] | None:
        self._check_open()
        if self.limit is not None and self.index >= self.limit:
            return None
        inj = self.faults
        if inj and inj.disconnect_due(self.delivered):
            raise SourceError(f"source {self.uri!r}: device disconnected (injected after {self.delivered} frames)")
        while inj.hit("drop", self.index):  # a dropped frame is never rendered: the sequence shows the gap
            self.index += 1
        plan = FramePlan(self.index, self._schedule)
        error = inj.hit("error", self.index)
        frames = [self._faulted(encode(self._render(plan, shutter), self.device.spec), error) for shutter in shutters]
        frames = self.frame_faults.apply_all(frames, self.index)
        self.index += 1
        self.delivered += 1
        return frames

    def _render(self, plan: FramePlan, shutter: str | None) -> Frame:
        if self.rig is None:
            return self.device.render(plan, shutter)
        rig, index = self.rig
        return rig.frame(index, plan.seq, shutter)

    def _faulted(self, frame: Frame, error: bool) -> Frame:
        p = self.faults.plan
        if not p:
            return frame
        return dataclasses.replace(frame, sequence=self.faults.sequence(frame.sequence),
                                   timestamp_ns=p.timestamp_ns(frame.timestamp_ns, self.start_ns),
                                   meta={**frame.meta, "error": True} if error else frame.meta)

    def read(self) -> Frame | None:
        """The next frame, or None after ``frames=N``."""
        got = self._next((None,))
        return None if got is None else got[0]

    def read_as(self, shutter: str) -> Frame | None:
        """The next frame rendered under ``shutter`` only."""
        got = self._next((shutter,))
        return None if got is None else got[0]

    def read_pair(self) -> tuple[Frame, Frame] | None:
        """Global and rolling frames of the same instant (same timestamp and exposure)."""
        got = self._next(("global", "rolling"))
        return None if got is None else (got[0], got[1])

    def ledger(self) -> Any:
        """The stream's energy and bandwidth ledger (``rollcam.firmware.ledger``; docs/insensor.md)."""
        return self.device.insensor.ledger(self.device.spec)

    def info(self) -> dict[str, Any]:
        """Sensor, size, timing and scene of the stream."""
        spec, cam = self.device.spec, self.camera
        s = spec.settings
        return {"uri": self.uri, "sensor": spec.sensor.name, "width": s.width, "height": s.height,
                "shutter": s.shutter, "readout": s.readout.value, "line_time_ns": s.timing.line_time_ns,
                "fps": s.timing.fps, "exposure_ns": s.exposure_ns, "exposure_clamped": s.clamped_exposure,
                "scene": spec.scene, "seed": spec.seed, "gain": spec.gain, "physics": spec.uses_physics,
                **(cam.pipeline.info() if cam.pipeline is not None else {}), "format": spec.output_format,
                **({} if spec.insensor is None else {"insensor": spec.insensor.network,
                                                     "insensor_output": spec.insensor.output})}


def open_source(uri: SourceURI) -> EmuSource:
    """Scheme entry point for ``emu:``."""
    if not uri.target:
        raise SourceError(f"source {uri.uri!r}: name a sensor, e.g. emu:imx219")
    return EmuSource(uri)


