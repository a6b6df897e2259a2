"""``emu:SENSOR?scene=..&seed=..`` -- an emulated sensor rendering a synthetic scene in process.

Options: ``scene`` (street | chart | flat), ``seed``, ``speed`` (static | normal | fast | multiplier),
``camera`` (index or name), ``time`` (dawn | morning | noon | afternoon | dusk), ``pedestrians`` (count),
``ego`` (none | pan | walk | vehicle | drone), ``vx`` (chart speed, px/s), ``level`` (flat-field radiance),
``shutter`` (rolling | global), ``readout``, ``exposure_us``, ``gain``, ``fps``, ``size`` (WxH),
``start_ns`` (device clock at frame 0), ``frames`` (stop after N frames; endless by default).

Sensor path: ``format`` (a V4L2 fourcc: BGR3 by default; raw Bayer/mono such as RGGB, RG10, pRAA, Y10, or
processed YUYV, NV12, YU12, GREY, RGB3), ``physics`` (on/off: exposure integration, EMVA noise and the ADC;
on by default for every format but BGR3, whose default is the clean render), ``blur_px`` (adaptive
motion-blur bound in pixels, default 0.5; 0 samples mid-exposure only), ``noise`` (on, off, or a comma list
of stages: shot, dark, read, dsnu, prnu, saturation), ``serial`` (device serial number: fixes DSNU/PRNU),
``noise_seed`` (temporal noise seed), ``hflip`` / ``vflip`` (on/off: mirrored readout; a vertical flip
scans the scene bottom-up, and a raw stream's Bayer order, hence fourcc, changes as the sensor's does).
Example: ``emu:imx219?format=pRAA&scene=flat&level=0.3&gain=2``.
"""

from __future__ import annotations

from typing import Any

from rollcam.common.errors import ConfigError, SourceError
from rollcam.common.values import parse_bool
from rollcam.sim.frame import Frame
from rollcam.sim.hwconfig import load_sensor
from rollcam.sim.noise import parse_stages
from rollcam.sim.scenegen import ego_preset, make_scene
from rollcam.sim.synthetic import SyntheticCamera

from .base import (
    CameraSource,
    SourceURI,
    finite_float,
    non_negative_float,
    non_negative_int,
    parse_size,
    positive_int,
)

OPTIONS = {"scene", "seed", "speed", "camera", "time", "pedestrians", "ego", "vx", "level", "shutter", "readout",
           "exposure_us", "gain", "fps", "size", "start_ns", "frames", "format", "physics", "blur_px", "noise",
           "serial", "noise_seed", "hflip", "vflip"}


def build_camera(sensor_name: str, opts: SourceURI) -> SyntheticCamera:
    """A SyntheticCamera from a sensor name and parsed ``emu:`` options."""
    opts.take(set(), OPTIONS)
    try:
        sensor = load_sensor(sensor_name)
    except ConfigError as exc:
        raise SourceError(f"source {opts.uri!r}: {exc}") from None
    kind = opts.get("scene", str, "street")
    size = opts.get("size", parse_size)
    mode = sensor.mode() if size is None else None
    width, height = size if size is not None else (mode.width, mode.height)
    misplaced = {"street": {"vx", "level"}, "chart": {"time", "speed", "pedestrians", "ego", "level"},
                 "flat": {"time", "speed", "pedestrians", "ego", "vx"}}.get(kind, set()) & set(opts.options)
    if misplaced:
        raise SourceError(f"source {opts.uri!r}: option(s) {sorted(misplaced)} do not apply to scene={kind!r}")
    scene_opts: dict[str, Any] = {"width": width, "height": height}
    try:
        if kind == "street":
            scene_opts.update(
                time_of_day=opts.get("time", str, "noon"),
                speed=opts.get("speed", str, "normal"),
                n_pedestrians=opts.get("pedestrians", non_negative_int, 20),
                ego=ego_preset(opts.get("ego", str, "none")),
            )
        elif kind == "chart":
            scene_opts["vx_px_s"] = opts.get("vx", finite_float, 2000.0)
        elif kind == "flat":
            scene_opts["level"] = opts.get("level", finite_float, 0.5)
        scene = make_scene(kind, opts.get("seed", non_negative_int, 0), **scene_opts)
        exposure_us = opts.get("exposure_us", finite_float)
        return SyntheticCamera(
            sensor, scene, opts.get("camera", str, "0"),
            start_ns=opts.get("start_ns", non_negative_int, 0),
            size=size,
            fps=opts.get("fps", finite_float),
            shutter=opts.get("shutter", str),
            readout=opts.get("readout", str),
            exposure_ns=None if exposure_us is None else round(exposure_us * 1000),
            gain=opts.get("gain", finite_float, 1.0),
            pixel_format=opts.get("format", str, "BGR3"),
            physics=opts.get("physics", parse_bool),
            blur_px=opts.get("blur_px", non_negative_float, 0.5),
            noise=parse_stages(opts.get("noise", str)),
            serial=opts.get("serial", str, "0"),
            noise_seed=opts.get("noise_seed", non_negative_int, 0),
            hflip=opts.get("hflip", parse_bool, False),
            vflip=opts.get("vflip", parse_bool, False),
        )
    except ConfigError as exc:
        raise SourceError(f"source {opts.uri!r}: {exc}") from None


class EmuSource(CameraSource):
    """Frames from a SyntheticCamera, in sequence, with exact timing and ground truth."""

    supports_pairs = True

    def __init__(self, uri: SourceURI) -> None:
        self.uri = uri.uri
        self.camera = build_camera(uri.target, uri)
        self.limit = uri.get("frames", positive_int)
        self.index = 0

    def read(self) -> Frame | None:
        """The next frame, or None after ``frames=N``."""
        self._check_open()
        if self.limit is not None and self.index >= self.limit:
            return None
        frame = self.camera.frame(self.index)
        self.index += 1
        return frame

    def read_as(self, shutter: str) -> Frame | None:
        """The next frame rendered under ``shutter`` only."""
        self._check_open()
        if self.limit is not None and self.index >= self.limit:
            return None
        frame = self.camera.frame(self.index, shutter)
        self.index += 1
        return frame

    def read_pair(self) -> tuple[Frame, Frame] | None:
        """Global and rolling frames of the same instant (same timestamp and exposure)."""
        self._check_open()
        if self.limit is not None and self.index >= self.limit:
            return None
        pair = (self.camera.frame(self.index, "global"), self.camera.frame(self.index, "rolling"))
        self.index += 1
        return pair

    def info(self) -> dict[str, Any]:
        """Sensor, size, timing and scene of the stream."""
        s = self.camera.settings
        return {"uri": self.uri, "sensor": self.camera.sensor.name, "width": s.width, "height": s.height,
                "shutter": s.shutter, "readout": s.readout.value, "line_time_ns": s.timing.line_time_ns,
                "fps": s.timing.fps, "exposure_ns": s.exposure_ns, "exposure_clamped": s.clamped_exposure,
                "scene": self.camera.scene.kind, "seed": self.camera.scene.seed,
                "format": self.camera.pixel_format, "physics": self.camera.physics,
                **(self.camera.pipeline.info() if self.camera.pipeline is not None else {})}


def open_source(uri: SourceURI) -> EmuSource:
    """Scheme entry point for ``emu:``."""
    if not uri.target:
        raise SourceError(f"source {uri.uri!r}: name a sensor, e.g. emu:imx219")
    return EmuSource(uri)
