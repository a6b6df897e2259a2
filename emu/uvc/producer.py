"""The camera behind the UVC function: the ``FrameProducer`` protocol, and an adapter over ``SyntheticCamera``.

The UVC device asks its producer for the sizes and frame intervals to advertise, programs it on commit, reads
exposure and gain through it, and takes frames by index with the device time each is read out by (for pacing
in real time). Any camera model that offers these methods can stand behind the UVC function.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from rollcam.common.errors import ConfigError, DeviceError
from rollcam.sim.frame import Frame
from rollcam.sim.hwconfig import SensorConfig
from rollcam.sim.scene import Scene
from rollcam.sim.synthetic import SyntheticCamera, resolve_settings

CONTROLS = ("exposure_ns", "gain")
"""Control names: exposure in integer ns; gain in hundredths of unity (100 = x1)."""

FPS_CHOICES = (120.0, 90.0, 60.0, 30.0, 25.0, 15.0, 10.0, 5.0)


@dataclass(frozen=True)
class ControlRange:
    """Limits of one integer control."""

    minimum: int
    maximum: int
    default: int
    step: int = 1


@runtime_checkable
class FrameProducer(Protocol):
    """What the UVC device needs from the camera it exposes."""

    name: str

    def sizes(self) -> Sequence[tuple[int, int]]:
        """Output sizes (width, height) offered, the default first."""

    def intervals_ns(self, width: int, height: int) -> Sequence[int]:
        """Frame periods (ns) offered at a size; the first is the default."""

    def configure(self, width: int, height: int, interval_ns: int) -> None:
        """Program size and frame period; frame indices restart at 0 from the device's current time."""

    def frame_due_ns(self, index: int) -> int:
        """Device time (ns) by which frame ``index`` has been read out and may be sent."""

    def frame(self, index: int) -> Frame:
        """Frame ``index`` of the current programming (BGR3 data, device-clock timestamps)."""

    def now_ns(self) -> int:
        """The device clock (ns)."""

    def control_range(self, name: str) -> ControlRange:
        """Limits of control ``name`` (one of ``CONTROLS``) under the current programming."""

    def get_control(self, name: str) -> int:
        """Current value of control ``name``."""

    def set_control(self, name: str, value: int) -> int:
        """Set control ``name``; returns the value applied (clamped to the range as the sensor would)."""


def offered_intervals_ns(sensor: SensorConfig, width: int, height: int, fps_choices: Sequence[float] = FPS_CHOICES,
                         shutter: str | None = None) -> list[int]:
    """Frame periods a camera offers at a size: the mode's own rate first, then the rates of ``fps_choices``
    the sensor can read that size at."""
    def period(fps: float | None) -> int | None:
        try:
            return resolve_settings(sensor, size=(width, height), fps=fps, shutter=shutter).timing.frame_period_ns
        except ConfigError:
            return None  # faster than the sensor reads this size

    native = period(None)
    assert native is not None
    others = {p for p in map(period, fps_choices) if p is not None} - {native}
    return [native, *sorted(others)]


class SyntheticProducer:
    """``FrameProducer`` over a ``SyntheticCamera``: rebuilds the camera when size, rate, exposure or gain change."""

    def __init__(self, sensor: SensorConfig, scene: Scene, camera: int | str = 0, *,
                 sizes: Sequence[tuple[int, int]] | None = None, fps_choices: Sequence[float] = FPS_CHOICES,
                 clock: Callable[[], int] = time.monotonic_ns, shutter: str | None = None) -> None:
        self.sensor, self.scene, self._camera_key, self._shutter = sensor, scene, camera, shutter
        self.name = sensor.name
        self._sizes = [tuple(s) for s in (sizes or [(m.width, m.height) for m in sensor.modes])]
        default = (sensor.mode().width, sensor.mode().height)
        if default in self._sizes:
            self._sizes.remove(default)
            self._sizes.insert(0, default)
        self._fps = tuple(fps_choices)
        self._clock = clock
        self._clock0 = clock()
        self._gain_x100 = 100
        self._exposure_ns: int | None = None
        w, h = self._sizes[0]
        self._size = (w, h)
        self._interval_ns = resolve_settings(sensor, size=(w, h), shutter=shutter).timing.frame_period_ns
        self._build(0)  # programmed for real (and the renderer warmed) by the host's commit

    def __repr__(self) -> str:
        return f"SyntheticProducer({self.cam!r})"

    def sizes(self) -> list[tuple[int, int]]:
        return list(self._sizes)

    def intervals_ns(self, width: int, height: int) -> list[int]:
        return offered_intervals_ns(self.sensor, width, height, self._fps, self._shutter)

    def configure(self, width: int, height: int, interval_ns: int) -> None:
        if (width, height) not in self._sizes:
            raise DeviceError(f"size {width}x{height} is not one of {self._sizes}")
        self._size, self._interval_ns = (width, height), int(interval_ns)
        self._build(0)
        # One render fills the renderer's caches (static layers, compiled kernels) before the timeline starts,
        # so a real-time stream does not open with a burst of dropped frames.
        self.cam.frame(0)
        self._start_ns = self.now_ns()

    def _build(self, start_ns: int) -> None:
        self._start_ns = start_ns
        try:
            self.cam = SyntheticCamera(self.sensor, self.scene, self._camera_key, size=self._size,
                                       fps=1e9 / self._interval_ns, shutter=self._shutter,
                                       exposure_ns=self._exposure_ns, gain=self._gain_x100 / 100)
        except ConfigError as exc:
            raise DeviceError(f"{self.name}: cannot program {self._size} at {self._interval_ns} ns: {exc}") from None

    def _start(self, index: int) -> int:
        return self.cam.settings.timing.frame_start_ns(index, self._start_ns)

    def frame_due_ns(self, index: int) -> int:
        s = self.cam.settings
        return self._start(index) + s.exposure_ns + int(s.timing.line_offset_ns(s.n_lines))

    def frame(self, index: int) -> Frame:
        return self.cam.render(index, self._start(index))

    def now_ns(self) -> int:
        return self._clock() - self._clock0

    def control_range(self, name: str) -> ControlRange:
        if name == "gain":
            g = self.sensor.gain
            return ControlRange(round(g.analog_min * 100), round(g.analog_max * g.digital_max * 100), 100)
        if name == "exposure_ns":
            s = self.cam.settings
            lo = resolve_settings(self.sensor, size=self._size, fps=1e9 / self._interval_ns, exposure_ns=0)
            hi = resolve_settings(self.sensor, size=self._size, fps=1e9 / self._interval_ns, exposure_ns=10**12)
            default = resolve_settings(self.sensor, size=self._size, fps=1e9 / self._interval_ns)
            return ControlRange(lo.exposure_ns, hi.exposure_ns, default.exposure_ns,
                                max(int(s.timing.line_offset_ns(1)), 1))
        raise DeviceError(f"control {name!r} is not one of {CONTROLS}")

    def get_control(self, name: str) -> int:
        self.control_range(name)
        return self._gain_x100 if name == "gain" else self.cam.settings.exposure_ns

    def set_control(self, name: str, value: int) -> int:
        r = self.control_range(name)
        value = min(max(int(value), r.minimum), r.maximum)
        if name == "gain":
            self._gain_x100 = value
        else:
            self._exposure_ns = value
        self._build(self._start_ns)  # same timeline: exposure and gain do not move frame starts
        return self.get_control(name)
