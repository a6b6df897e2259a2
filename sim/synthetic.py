"""A simulated sensor looking at a scene: Frames with exact device timing and ground truth.

``SyntheticCamera`` joins a sensor description (timing, optics, shutter, readout) to a scene camera and the
per-line renderer. Frame ``n`` starts exposing at ``start_ns + frame_start(n)`` (closed form from the pixel
clock, exact after any uptime). Each line is sampled at the middle of its exposure window, the centroid of
what a real pixel integrates: a global-shutter frame samples every line at ``timestamp + exposure / 2``, a
rolling-shutter frame line ``k`` (in readout order) ``line_offset(k)`` later. Brightness scales with
exposure and gain relative to the sensor's default exposure.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from .errors import ConfigError
from .frame import Frame
from .hwconfig import SensorConfig
from .render import LineTruth, Renderer
from .scene import Scene
from .timing import LineTiming, Readout, line_sample_times_ns

DEFAULT_EXPOSURE_NS = 10_000_000
SHUTTERS = ("rolling", "global")


@dataclass(frozen=True)
class StreamSettings:
    """The resolved settings of a synthetic stream (what the sensor would be programmed with)."""

    width: int
    height: int
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


def resolve_settings(
    sensor: SensorConfig,
    *,
    size: tuple[int, int] | None = None,
    fps: float | None = None,
    shutter: str | None = None,
    readout: str | Readout | None = None,
    exposure_ns: int | None = None,
    gain: float = 1.0,
) -> StreamSettings:
    """Sensor programming for a stream: mode by size, frame length by fps, exposure clamped to the frame."""
    mode = None
    if size is not None:
        w, h = size
        if w <= 0 or h <= 0:
            raise ConfigError(f"size must be positive, got {w}x{h}")
        mode = next((m for m in sensor.modes if (m.width, m.height) == (w, h)), None)
    mode = mode or sensor.mode()
    base = sensor.timing(mode)
    width, height = (mode.width, mode.height) if size is None else size
    # An output size no mode has is a rescaled readout of the mode: the same readout time spread over the
    # output lines, expressed exactly by scaling pixel rate and line length.
    n_mode = mode.width if Readout.parse(readout or sensor.readout).by_column else mode.height
    n_out = width if Readout.parse(readout or sensor.readout).by_column else height
    if n_out != n_mode:
        frame_lines = -(-base.frame_length_lines * n_out // n_mode)
        timing = LineTiming(base.pixel_rate_hz * n_out, base.line_length_pck * n_mode, frame_lines)
    else:
        timing = base
    if fps is not None:
        if not np.isfinite(fps) or fps <= 0:
            raise ConfigError(f"fps must be a positive number, got {fps!r}")
        lines = round(timing.pixel_rate_hz / (timing.line_length_pck * fps))
        if lines < n_out:
            max_fps = timing.pixel_rate_hz / (timing.line_length_pck * n_out)
            raise ConfigError(
                f"fps={fps!r} is above the sensor's maximum {max_fps:.3f} for {width}x{height}"
                f" (frame length {lines} lines < {n_out} output lines)"
            )
        timing = LineTiming(timing.pixel_rate_hz, timing.line_length_pck, lines)
    shutter = shutter or sensor.shutter
    if shutter not in SHUTTERS:
        raise ConfigError(f"shutter {shutter!r} is not one of {SHUTTERS}")
    ro = Readout.parse(readout or sensor.readout)
    # Exposure in whole lines between the sensor's limits, as a real sensor's integration register holds it.
    max_lines = max(timing.frame_length_lines - sensor.exposure.max_margin_lines, sensor.exposure.min_lines)
    want_ns = DEFAULT_EXPOSURE_NS if exposure_ns is None else int(exposure_ns)
    if want_ns < 0:
        raise ConfigError(f"exposure must be >= 0 ns, got {want_ns!r}")
    lines = round(want_ns / max(timing.line_offset_ns(1), 1))
    clamped = not sensor.exposure.min_lines <= lines <= max_lines
    lines = min(max(lines, sensor.exposure.min_lines), max_lines)
    exp_ns = int(timing.line_offset_ns(lines))
    if not np.isfinite(gain) or gain <= 0:
        raise ConfigError(f"gain must be a positive number, got {gain!r}")
    return StreamSettings(width, height, timing, ro, shutter, exp_ns, float(gain), clamped)


class SyntheticCamera:
    """Frames of one scene camera as a given sensor would deliver them, with exact ground truth."""

    def __init__(self, sensor: SensorConfig, scene: Scene, camera: int | str = 0, *, start_ns: int = 0,
                 **settings) -> None:
        self.sensor = sensor
        self.scene = scene
        self.settings = resolve_settings(sensor, **settings)
        s = self.settings
        mode = sensor.mode(f"{s.width}x{s.height}") if any(
            (m.width, m.height) == (s.width, s.height) for m in sensor.modes) else sensor.mode()
        crop = sensor.crop(mode)
        # The output covers the mode's crop of the array; its width in mm fixes the focal length in pixels.
        covered_mm = crop.width * sensor.optics.pixel_size_um / 1000.0
        cam = scene.camera(camera).with_resolution(s.width, s.height, sensor.optics.focal_mm, covered_mm)
        self.camera = cam
        ref_exposure = resolve_settings(sensor, size=(s.width, s.height)).exposure_ns
        brightness = s.gain * s.exposure_ns / max(ref_exposure, 1)
        self.renderer = Renderer(scene, cam, gain=brightness)
        self.start_ns = int(start_ns)

    def __repr__(self) -> str:
        s = self.settings
        return (f"SyntheticCamera({self.sensor.name!r}, scene={self.scene.kind}#{self.scene.seed}, "
                f"{s.width}x{s.height} {s.shutter} {s.readout.value}, {s.timing.fps:.2f} fps, "
                f"exposure {s.exposure_ns} ns)")

    def timestamp_ns(self, index: int) -> int:
        """Start of exposure of frame ``index``'s first line, device clock."""
        return self.settings.timing.frame_start_ns(index, self.start_ns)

    def line_times_ns(self, index: int, shutter: str | None = None) -> np.ndarray:
        """Sample time of every image line of frame ``index`` under ``shutter`` (default: the stream's)."""
        s = self.settings
        shutter = shutter or s.shutter
        t0 = self.timestamp_ns(index) + s.exposure_ns // 2
        timing = s.timing if shutter == "rolling" else None
        return line_sample_times_ns(t0, s.n_lines, timing, s.readout)

    def frame(self, index: int, shutter: str | None = None) -> Frame:
        """Render frame ``index`` (optionally under the other shutter, for paired GS/RS data)."""
        s = self.settings
        shutter = shutter or s.shutter
        if shutter not in SHUTTERS:
            raise ConfigError(f"shutter {shutter!r} is not one of {SHUTTERS}")
        times = self.line_times_ns(index, shutter)
        by_col = s.readout.by_column
        res = self.renderer.render_lines(times, by_column=by_col)
        t_ref = self.timestamp_ns(index) + s.exposure_ns // 2
        gs_truth: LineTruth | None = res.truth if shutter == "global" else None
        objects = self.renderer.object_truth(res.truth, t_ref, by_column=by_col, gs_truth=gs_truth)
        meta = {"scene": self.scene.kind, "seed": self.scene.seed, "camera": self.camera.name,
                "time_of_day": self.scene.time_of_day}
        return Frame(
            data=res.image,
            format="BGR3",
            sequence=index,
            timestamp_ns=self.timestamp_ns(index),
            line_time_ns=s.timing.line_time_ns if shutter == "rolling" else 0,
            readout=s.readout,
            exposure_ns=s.exposure_ns,
            shutter=shutter,
            row_times_ns=times,
            objects=objects,
            meta=meta,
        )

    def frames(self, n: int | None = None, shutter: str | None = None, first: int = 0) -> Iterator[Frame]:
        """Consecutive frames (forever when ``n`` is None)."""
        i = first
        while n is None or i < first + n:
            yield self.frame(i, shutter)
            i += 1
