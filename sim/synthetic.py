"""A simulated sensor looking at a scene: Frames with exact device timing and ground truth.

``SyntheticCamera`` joins a sensor description (timing, optics, shutter, readout) to a scene camera and the
per-line renderer. Frame ``n`` starts exposing at ``start_ns + frame_start(n)`` (closed form from the pixel
clock, exact after any uptime). Each line is sampled at the middle of its exposure window, the centroid of
what a real pixel integrates: a global-shutter frame samples every line at ``timestamp + exposure / 2``, a
rolling-shutter frame line ``k`` (in readout order) ``line_offset(k)`` later. Brightness scales with
exposure and gain relative to the sensor's default exposure.

With ``physics`` (the default for any ``pixel_format`` but BGR3) frames go through the sensor model
instead: each line integrates the scene over its own exposure window with adaptive motion-blur sampling
(``rollcam.sim.exposure``, bound ``blur_px``; None samples mid-exposure only), then EMVA 1288 noise, the
ADC, and the requested raw layout or the preview ISP (``rollcam.sim.sensor``). Ground truth stays the
mid-exposure one.

``optics`` (a ``rollcam.sim.optics.LensOptics``: vignetting, PSF) puts a lens in front of the sensor: on the
sensor path it acts on the integrated radiance before the EMVA model, on the clean path on the linear render
before its 8-bit encoding; off (the default) it does no work.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.common.values import SERIAL

from .defects import SensorDefects
from .exposure import DEFAULT_BOUND_PX, integrate, plan_samples
from .formats import pixel_format as fourcc_of
from .frame import Box, Frame, ObjectTruth
from .hwconfig import SensorConfig, SensorMode
from .optics import LensOptics, LensStage, runs
from .render.renderer import Renderer, encode_linear
from .render.result import LinearFrame, LineTruth
from .scene import Scene
from .sensor import SensorPipeline, flip
from .timing import LineTiming, Readout, line_sample_times_ns

DEFAULT_EXPOSURE_NS = 10_000_000
SHUTTERS = ("rolling", "global")


MIN_FPS = 1e-3  # a 1000 s frame period: slower streams are a misconfiguration, not a sensor


@dataclass(frozen=True)
class StreamSettings:
    """The resolved settings of a synthetic stream (what the sensor would be programmed with)."""

    width: int
    height: int
    mode: SensorMode
    timing: LineTiming
    readout: Readout
    shutter: str
    exposure_ns: int
    gain: float
    clamped_exposure: bool

    @property
    def n_lines(self) -> int:
        """Lines read per frame: rows, or columns for column readout."""
        return self.width if self.readout.by_column else self.height


def _finite(name: str, value: float, low: float = 0.0) -> float:
    if not isinstance(value, (int, float, np.number)) or not math.isfinite(value) or value <= low:
        raise ConfigError(f"{name} must be a finite number > {low:g}, got {value!r}")
    return float(value)


def _reduced(pixel_rate_hz: int, line_length_pck: int, frame_lines: int, frame_pck: int) -> LineTiming:
    g = math.gcd(pixel_rate_hz, line_length_pck, frame_pck)
    return LineTiming(pixel_rate_hz // g, line_length_pck // g, frame_lines, frame_pck // g)


def resolve_settings(
    sensor: SensorConfig,
    *,
    size: tuple[int, int] | None = None,
    fps: float | None = None,
    shutter: str | None = None,
    readout: str | Readout | None = None,
    exposure_ns: int | None = None,
    gain: float = 1.0,
    frame_length_lines: int | None = None,
    line_length_pck: int | None = None,
) -> StreamSettings:
    """Sensor programming for a stream: mode by size, frame length by fps, exposure clamped to the frame.

    The mode's timing reads ``mode.height`` rows per readout. An output of another size, or read by
    columns, is a rescaled readout: the same readout time spread over the output's lines, and the same
    frame period (kept exact by counting it in pixel clocks, scaled with the clock). ``frame_length_lines``
    and ``line_length_pck`` program the frame and line length directly (in the timing's own lines and
    clocks, as registers hold them) instead of ``fps``.
    """
    mode = None
    if size is not None:
        w, h = size
        if w <= 0 or h <= 0:
            raise ConfigError(f"size must be positive, got {w}x{h}")
        mode = next((m for m in sensor.modes if (m.width, m.height) == (w, h)), None)
    mode = mode or sensor.mode()
    width, height = (mode.width, mode.height) if size is None else size
    ro = Readout.parse(readout or sensor.readout)
    base = sensor.timing(mode)
    n_out = width if ro.by_column else height
    timing = base
    if n_out != mode.height:
        frame_pck = base.frame_period_pck * n_out
        line_pck = base.line_length_pck * mode.height
        timing = _reduced(base.pixel_rate_hz * n_out, line_pck, -(-frame_pck // line_pck), frame_pck)
    if fps is not None and frame_length_lines is not None:
        raise ConfigError("give fps or a frame length, not both")
    if frame_length_lines is not None or line_length_pck is not None:  # fps, if given, then uses this line length
        for name, value in (("frame_length_lines", frame_length_lines), ("line_length_pck", line_length_pck)):
            if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer))
                                      or value < 1):
                raise ConfigError(f"{name} must be a whole number >= 1, got {value!r}")
        lines = timing.frame_length_lines if frame_length_lines is None else int(frame_length_lines)
        if lines < n_out:
            raise ConfigError(f"frame length {lines} lines is shorter than the {n_out} output lines of "
                              f"{width}x{height}")
        timing = LineTiming(timing.pixel_rate_hz, int(line_length_pck or timing.line_length_pck), lines)
    if fps is not None:
        fps = _finite("fps", fps)
        frame_s = 1.0 / max(fps, MIN_FPS)
        if fps < MIN_FPS:
            raise ConfigError(f"fps={fps!r} is below the minimum {MIN_FPS:g}")
        lines = max(round(timing.pixel_rate_hz * frame_s / timing.line_length_pck), 1)
        if lines < n_out:
            max_fps = timing.pixel_rate_hz / (timing.line_length_pck * n_out)
            raise ConfigError(
                f"fps={fps!r} is above the sensor's maximum {max_fps:.3f} for {width}x{height}"
                f" (frame length {lines} lines < {n_out} output lines)"
            )
        timing = LineTiming(timing.pixel_rate_hz, timing.line_length_pck, lines)
    if timing.frame_period_pck < n_out * timing.line_length_pck:
        raise ConfigError(f"{width}x{height} read by {ro.value} needs {n_out} lines, more than one frame period "
                          f"of sensor {sensor.name!r} holds")
    shutter = shutter or sensor.shutter
    if shutter not in SHUTTERS:
        raise ConfigError(f"shutter {shutter!r} is not one of {SHUTTERS}")
    # Exposure in whole lines between the sensor's limits, as a real sensor's integration register holds
    # it, and never longer than the frame.
    frame_lines = timing.frame_period_pck // timing.line_length_pck
    max_lines = min(max(frame_lines - sensor.exposure.max_margin_lines, sensor.exposure.min_lines), frame_lines)
    want_ns = DEFAULT_EXPOSURE_NS if exposure_ns is None else exposure_ns
    if not isinstance(want_ns, (int, np.integer)) or want_ns < 0:
        raise ConfigError(f"exposure must be a whole number of ns >= 0, got {want_ns!r}")
    lines = round(int(want_ns) / max(timing.line_offset_ns(1), 1))
    clamped = not sensor.exposure.min_lines <= lines <= max_lines
    lines = max(min(max(lines, sensor.exposure.min_lines), max_lines), 1)
    exp_ns = int(timing.line_offset_ns(lines))
    return StreamSettings(width, height, mode, timing, ro, shutter, exp_ns, _finite("gain", gain), clamped)


_REVERSED = {Readout.TOP_TO_BOTTOM: Readout.BOTTOM_TO_TOP, Readout.BOTTOM_TO_TOP: Readout.TOP_TO_BOTTOM,
             Readout.LEFT_TO_RIGHT: Readout.RIGHT_TO_LEFT, Readout.RIGHT_TO_LEFT: Readout.LEFT_TO_RIGHT}


def _flip_box(b: Box | None, w: int, h: int, hflip: bool, vflip: bool) -> Box | None:
    if b is None:
        return None
    x0, y0, x1, y1 = b
    if hflip:
        x0, x1 = w - x1, w - x0
    if vflip:
        y0, y1 = h - y1, h - y0
    return (x0, y0, x1, y1)


def _flip_truth(o: ObjectTruth, w: int, h: int, hflip: bool, vflip: bool) -> ObjectTruth:
    return dataclasses.replace(o, box_gs=_flip_box(o.box_gs, w, h, hflip, vflip),
                               box_rs=_flip_box(o.box_rs, w, h, hflip, vflip))


class SyntheticCamera:
    """Frames of one scene camera as a given sensor would deliver them, with exact ground truth."""

    def __init__(self, sensor: SensorConfig, scene: Scene, camera: int | str = 0, *, start_ns: int = 0,
                 pixel_format: str = "BGR3", physics: bool | None = None, blur_px: float | None = DEFAULT_BOUND_PX,
                 noise: frozenset[str] | None = None, serial: str = SERIAL, noise_seed: int = 0, hflip: bool = False,
                 vflip: bool = False, optics: LensOptics | None = None, settings: StreamSettings | None = None,
                 defects: SensorDefects | None = None, mount: tuple[float, float, float, float] | None = None,
                 ego_path: bool = False,
                 **programming) -> None:
        self.sensor = sensor
        self.scene = scene
        if settings is not None and programming:
            raise ConfigError(f"give resolved settings or {sorted(programming)}, not both")
        self.settings = settings or resolve_settings(sensor, **programming)
        s = self.settings
        crop = sensor.crop(s.mode)
        # The output covers the mode's crop of the array; its width in mm fixes the focal length in pixels.
        covered_mm = crop.width * sensor.optics.pixel_size_um / 1000.0
        cam = scene.camera(camera).with_resolution(s.width, s.height, sensor.optics.focal_mm, covered_mm)
        if mount is not None:  # one camera of a rig (rollcam.firmware.rig): right, forward, up in m, yaw in deg
            cam = cam.mounted(mount[:3], mount[3])
        self.camera = cam
        # Brightness is relative to the default exposure of the same readout (same line time), so it
        # scales with the requested exposure and gain only.
        ref_exposure = resolve_settings(sensor, size=(s.width, s.height), readout=s.readout).exposure_ns
        brightness = s.gain * s.exposure_ns / max(ref_exposure, 1)
        self.renderer = Renderer(scene, cam, gain=brightness, light_window_ns=s.exposure_ns)
        self._start_ns = int(start_ns)
        self.pixel_format = fourcc_of(pixel_format).fourcc
        self.physics = self.pixel_format != "BGR3" if physics is None else bool(physics)
        if not self.physics and self.pixel_format != "BGR3":
            raise ConfigError(f"pixel format {pixel_format!r} needs the sensor model (physics on)")
        self.blur_px = blur_px or None
        self.ego_path = bool(ego_path)  # a moving camera's blur along each pixel's path (sim.exposure), not lines
        self.optics = optics or LensOptics()
        self._lens = LensStage(self.optics)  # keeps the lens image of the renderer's static composite
        self._lens_u8: tuple[np.ndarray, np.ndarray] | None = None  # (that image, its 8-bit encoding)
        self.pipeline: SensorPipeline | None = None
        self.defects = defects  # injected sensor defects (``rollcam.sim.defects``), made on the ADC samples
        # The ADC samples (uint16 H x W, output orientation) of the last frame made through the sensor model: the
        # raw mosaic an in-sensor network reads even when the stream's format is an ISP picture.
        self.last_samples: np.ndarray | None = None
        # Radiance scratch of the sensor path, reused frame to frame: each frame is delivered (copied into its
        # fourcc layout) before the next render, and a reused buffer's pages are already mapped.
        self._radiance_buf: np.ndarray | None = None
        if self.physics:
            self.pipeline = SensorPipeline.for_sensor(sensor, self.pixel_format, gain=s.gain, serial=serial,
                                                      seed=noise_seed, stages=noise, origin=(crop.top, crop.left),
                                                      hflip=hflip, vflip=vflip, size=(s.width, s.height))
            self.pixel_format = self.pipeline.fourcc
        self.hflip, self.vflip = bool(hflip), bool(vflip)
        # A flipped readout scans the scene the other way: a vertical flip of a row readout (or a horizontal
        # flip of a column readout) reads the scene's last line first.
        scan_flip = vflip if not s.readout.by_column else hflip
        self.scan_readout = _REVERSED[s.readout] if scan_flip else s.readout

    def __repr__(self) -> str:
        s = self.settings
        return (f"SyntheticCamera({self.sensor.name!r}, scene={self.scene.kind}#{self.scene.seed}, "
                f"{s.width}x{s.height} {s.shutter} {s.readout.value}, {s.timing.fps:.2f} fps, "
                f"exposure {s.exposure_ns} ns)")

    @property
    def start_ns(self) -> int:
        """Device time at which frame 0 starts exposing (fixed at construction; ``render`` takes any start)."""
        return self._start_ns

    def timestamp_ns(self, index: int) -> int:
        """Start of exposure of frame ``index``'s first line, device clock."""
        return self.settings.timing.frame_start_ns(index, self._start_ns)

    def line_times_ns(self, index: int, shutter: str | None = None, timestamp_ns: int | None = None) -> np.ndarray:
        """Sample time of every scene line of frame ``index`` under ``shutter`` (default: the stream's).

        These are the render's times, in scene orientation; a flipped stream's ``Frame.row_times_ns`` are
        the same times mirrored into output orientation. ``timestamp_ns`` overrides the frame's start.
        """
        s = self.settings
        shutter = shutter or s.shutter
        start = self.timestamp_ns(index) if timestamp_ns is None else int(timestamp_ns)
        timing = s.timing if shutter == "rolling" else None
        return line_sample_times_ns(start + s.exposure_ns // 2, s.n_lines, timing, self.scan_readout)

    def frame(self, index: int, shutter: str | None = None) -> Frame:
        """Render frame ``index`` at its place in this camera's timeline (optionally under the other shutter,
        for paired GS/RS data)."""
        return self.render(index, self.timestamp_ns(index), shutter)

    def render(self, index: int, timestamp_ns: int, shutter: str | None = None) -> Frame:
        """Frame ``index`` (its sequence number and temporal-noise draw) exposed from device time
        ``timestamp_ns``: the camera holds no clock, each frame's start is given."""
        s = self.settings
        shutter = shutter or s.shutter
        if shutter not in SHUTTERS:
            raise ConfigError(f"shutter {shutter!r} is not one of {SHUTTERS}")
        timestamp_ns = int(timestamp_ns)
        times = self.line_times_ns(index, shutter, timestamp_ns)
        by_col = s.readout.by_column
        data, fourcc, extra = None, "BGR3", {}
        if self.pipeline is not None:
            res, data, extra = self._sensor_frame(index, times, shutter)
            fourcc = self.pipeline.fourcc
        elif self.optics.on:  # the lens acts on linear radiance, before the 8-bit encoding
            res = self.renderer.render_linear(times, by_column=by_col, out=self._radiance(by_col))
            assert res.radiance is not None
            image = self._encode(self._lens.radiance(res.radiance))
            res.image = np.ascontiguousarray(image.transpose(1, 0, 2)) if by_col else image
            extra = {"optics": self.optics.info()}
        else:
            res = self.renderer.render_lines(times, by_column=by_col)
        t_ref = timestamp_ns + s.exposure_ns // 2
        gs_truth: LineTruth | None = res.truth if shutter == "global" else None
        objects = self.renderer.object_truth(res.truth, t_ref, by_column=by_col, gs_truth=gs_truth)
        meta = {"scene": self.scene.kind, "seed": self.scene.seed, "camera": self.camera.name,
                "time_of_day": self.scene.time_of_day, **extra}
        if s.clamped_exposure:
            meta["exposure_clamped"] = True
        if self.scene.lights:
            meta["lights"] = [f"{li.name}: {li.waveform.describe()}" for li in self.scene.lights]
        if data is None:
            data = np.ascontiguousarray(flip(res.image, self.hflip, self.vflip))
        if self.hflip or self.vflip:
            objects = tuple(_flip_truth(o, s.width, s.height, self.hflip, self.vflip) for o in objects)
            out_flip = self.vflip if not by_col else self.hflip
            times = times[::-1].copy() if out_flip else times
        return Frame(
            data=data,
            format=fourcc,
            size=(s.width, s.height),
            sequence=index,
            timestamp_ns=timestamp_ns,
            line_time_ns=s.timing.line_time_ns if shutter == "rolling" else 0,
            readout=s.readout,
            exposure_ns=s.exposure_ns,
            shutter=shutter,
            row_times_ns=times,
            objects=objects,
            meta=meta,
        )

    def _sensor_frame(self, index: int, mid_times: np.ndarray, shutter: str):
        """Truth render at mid-exposure, radiance integrated over each line's window, sensor output."""
        s, pipe = self.settings, self.pipeline
        assert pipe is not None
        by_col = s.readout.by_column
        starts = mid_times - s.exposure_ns // 2
        extra: dict = pipe.info()
        if self.blur_px is None:
            # Linear only, static lines read in place from the renderer's cache (no frame-sized copies).
            res = self.renderer.render_linear(mid_times, by_column=by_col, out=self._radiance(by_col))
            radiance = res.radiance
            extra["blur_samples_max"] = 1
        else:
            # ego_path: a moving camera's background integrated along each pixel's path (one render, cheap
            # reads; its error per preset is in docs/sensor-model.md), else whole-line samples.
            plan = plan_samples(self.renderer, starts, s.exposure_ns, by_column=by_col, bound_px=self.blur_px,
                                ego_path=self.ego_path)
            radiance = integrate(self.renderer, plan, by_column=by_col, out=self._radiance(by_col)).radiance
            res = self.renderer.render_lines(mid_times, by_column=by_col, truth_only=True)
            extra.update(blur_bound_px=self.blur_px, blur_samples_max=int(plan.n.max()),
                         blur_evaluations=plan.evaluations, blur_capped=plan.capped)
            if plan.path_n is not None:
                extra["blur_path_samples_max"] = int(plan.path_n.max())
        assert radiance is not None
        if self.optics.on:  # the lens, on the light each pixel integrated, before the sensor's noise
            radiance = self._lens.radiance(radiance)
            extra["optics"] = self.optics.info()
        dn = pipe.samples(radiance, s.exposure_ns, index)
        if self.defects is not None:  # only when injected: no cost otherwise
            dn, extra["defects"] = self.defects.apply(
                dn, index, s.exposure_ns, gain=pipe.analog_gain * pipe.digital_gain,
                black_dn=pipe.model.noise.black_level_dn, max_dn=pipe.model.max_dn, cfa=pipe.model.cfa,
                hflip=self.hflip, vflip=self.vflip)
        self.last_samples = dn
        return res, pipe.encode(dn), extra

    def _radiance(self, by_column: bool) -> np.ndarray:
        """The reusable float32 radiance buffer of a render in this orientation."""
        shape = (*self.renderer.render_shape(by_column), 3)
        if self._radiance_buf is None or self._radiance_buf.shape != shape:
            self._radiance_buf = np.empty(shape, np.float32)
        return self._radiance_buf

    def _encode(self, lens: LinearFrame) -> np.ndarray:
        """The 8-bit image (render orientation) of the lens's radiance: the static composite's lens image encoded
        once, then only the lines the lens re-filtered."""
        if lens.static is None:
            return encode_linear(lens.lines, self.renderer.gain)
        if self._lens_u8 is None or self._lens_u8[0] is not lens.static:
            self._lens_u8 = (lens.static, encode_linear(lens.static, self.renderer.gain))
        image = self._lens_u8[1].copy()
        for a, b in runs(lens.painted):
            image[a:b] = encode_linear(lens.lines[a:b], self.renderer.gain)
        return image

    def frames(self, n: int | None = None, shutter: str | None = None, first: int = 0) -> Iterator[Frame]:
        """Consecutive frames (forever when ``n`` is None)."""
        i = first
        while n is None or i < first + n:
            yield self.frame(i, shutter)
            i += 1
