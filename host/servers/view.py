"""``rollcam view SOURCE``: the live page of ``rollcam emulate --http`` for any source, served host side.

A ``SourcePump`` reads the source on its own thread and hands each frame to the frame sinks of an
``MjpegServer`` (the same encoder, slots and limits as the emulator's stream) and of its ``LiveView``.
Recorded and emulated sources are paced by their own timestamps (a file plays at its rate, not as fast as it
decodes); live ones come at their own pace. The page's controls are what the source has: an ``emu:`` source
has the emulated camera's (``CameraControls``), an OpenCV/V4L2 camera its frame rate, exposure and gain,
others none. ``detector_annotator`` turns a detector into the view's ``annotate`` callback (used by
``rollcam emulate --detector`` too).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

from rollcam.common.errors import ConfigError, DeviceError
from rollcam.common.lifecycle import Closeable, Stats, Worker
from rollcam.common.values import finite_float
from rollcam.firmware.stream import CameraStats
from rollcam.sim.frame import Frame

from ..sources.base import CameraSource

REANCHOR_NS = 1_000_000_000  # further behind its timestamps than this, a paced source starts its clock anew
# What the MJPEG encoder reads of a sensor when a source names none: its frames are pictures (no black level).
PICTURE_SENSOR = SimpleNamespace(name="picture", bit_depth=8, noise=SimpleNamespace(black_level_dn=0.0))


def detector_annotator(detector: Any) -> Callable[[Frame], list[dict[str, Any]]]:
    """The live view's ``annotate``: ``detector`` on a frame's preview (or raw data), boxes as plain dicts."""
    from ..preview import frame_bgr

    names = getattr(detector, "class_names", {})

    def annotate(frame: Frame) -> list[dict[str, Any]]:
        image = frame.data if detector.input == "raw" else frame_bgr(frame)
        return [{**d, "class_name": names.get(d["cls"], str(d["cls"]))} for d in detector.detect(image).to_json()]

    return annotate


@dataclass
class SourcePumpStats(Stats):
    """Frames read and delivered, and how far behind its timestamps the source ran at worst."""

    frames: int = 0
    max_behind_ns: int = 0
    ended: bool = False


class SourceCamera:
    """What an ``MjpegServer`` reads of its camera, for a host source: a sensor (levels), counters."""

    def __init__(self, source: CameraSource) -> None:
        self.source = source
        device = getattr(source, "device", None)
        self.sensor = device.sensor if device is not None else _named_sensor(source) or PICTURE_SENSOR
        self.stats = CameraStats()

    def stream_on(self) -> None:
        """A host source streams once opened."""


def _named_sensor(source: CameraSource) -> Any:
    name = source.info().get("sensor")
    if not name:
        return None
    from rollcam.sim.hwconfig import load_sensor

    return load_sensor(str(name))


class SourcePump(Closeable):
    """A thread reading ``source`` and feeding sinks (``on_frame(frame, None)``), as ``FramePump`` feeds them
    from an emulated camera; ``paced`` holds frames to their timestamps' rate."""

    def __init__(self, source: CameraSource, camera: SourceCamera, *, paced: bool = True,
                 clock: Callable[[], int] = time.monotonic_ns) -> None:
        self.source, self.camera, self.paced, self.clock = source, camera, paced, clock
        self.stats = SourcePumpStats()
        self._sinks: list[Any] = []
        self._worker = Worker(self._run, name="rollcam-view-source", wrap=DeviceError)

    def add_sink(self, sink: Any) -> None:
        self._sinks = [*self._sinks, sink]

    def remove_sink(self, sink: Any) -> None:
        self._sinks = [s for s in self._sinks if s is not sink]

    def start(self) -> None:
        self._worker.start()

    def check(self) -> None:
        """Raise (as a DeviceError) what stopped the reading thread, if anything did."""
        self._worker.check()

    def _close(self) -> None:
        self._worker.close()

    def _run(self) -> None:
        anchor: tuple[int, int] | None = None  # (host ns, frame timestamp ns) the pacing counts from
        while not self._worker.stopping:
            frame = self.source.read()
            if frame is None:
                self.stats.ended = True
                return
            if self.paced:
                now, ts = self.clock(), int(frame.timestamp_ns)
                if anchor is None or ts < anchor[1]:
                    anchor = (now, ts)
                wait_ns = anchor[0] + ts - anchor[1] - now
                if wait_ns < -REANCHOR_NS:
                    anchor = (now, ts)
                self.stats.max_behind_ns = max(self.stats.max_behind_ns, -wait_ns)
                if wait_ns > 0 and self._worker.stop_event.wait(wait_ns / 1e9):
                    return
            self.camera.stats.frames += 1
            self.stats.frames += 1
            for sink in self._sinks:
                sink.on_frame(frame, None)


class OpenCVControls:
    """The page's controls of an OpenCV/V4L2 camera: the numbers its backend reports (fps, exposure, gain)."""

    def __init__(self, source: Any) -> None:
        self.source = source
        self._version = object()

    def describe(self) -> dict[str, dict[str, Any]]:
        return {name: {"label": name, "kind": "number", "unit": "", "value": f"{value:g}", "choices": None,
                       "idle_only": False}
                for name, value in self.source.controls().items() if value >= 0}

    def apply(self, name: str, value: str) -> str:
        if name not in self.describe():
            raise ConfigError(f"no control {name!r}; this camera has {sorted(self.describe())}")
        try:
            number = finite_float(value)
        except ValueError as exc:
            raise ConfigError(f"control {name!r}: {value!r} is not a number ({exc})") from None
        if not self.source.set_control(name, number):
            raise DeviceError(f"the camera refused {name}={value!r}")
        self._version = object()
        return f"{self.source.controls()[name]:g}"

    def version(self) -> object:
        return self._version


def controls_of(source: CameraSource) -> Any:
    """What the page may change on ``source``: the emulated camera's controls, a camera's, or none."""
    from rollcam.emu.http.view_controls import CameraControls, NoControls

    device = getattr(source, "device", None)
    if device is not None:
        return CameraControls(device)
    if callable(getattr(source, "set_control", None)) and callable(getattr(source, "controls", None)):
        return OpenCVControls(source)
    return NoControls()


@dataclass
class ViewServer(Closeable):
    """A running ``rollcam view``: the source, its pump, the MJPEG server and the live view on it."""

    source: CameraSource
    pump: SourcePump
    server: Any
    view: Any

    def _close(self) -> None:
        try:
            self.view.close()
            self.server.close()
        finally:
            try:
                self.pump.close()
            finally:
                self.source.close()


def open_view(source: CameraSource, host: str = "127.0.0.1", port: int = 0, *, quality: int | None = None,
              detector: Any = None, token: str | None = "auto", paced: bool = True) -> ViewServer:
    """Serve the live page of ``source`` (opened; it is closed with the server) on ``host:port``, started."""
    from rollcam.emu.http.mjpeg import MjpegServer
    from rollcam.emu.http.view import LiveView

    camera = SourceCamera(source)
    pump = SourcePump(source, camera, paced=paced)
    kwargs = {} if quality is None else {"quality": quality}
    try:
        server = MjpegServer(camera, host, port, pump=pump, **kwargs)  # type: ignore[arg-type]
    except OSError as exc:
        pump.close()
        source.close()
        raise OSError(f"cannot serve HTTP on {host}:{port}: {exc.strerror or exc}") from None
    info = source.info()  # once: the page's header; a source's info() need not be safe beside its read()
    view = LiveView(server, controls_of(source), token=token, info=lambda: info,
                    annotate=None if detector is None else detector_annotator(detector))
    running = ViewServer(source, pump, server, view)
    try:
        server.start()
    except BaseException:
        running.close()
        raise
    return running
