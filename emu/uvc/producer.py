"""The camera behind the UVC function: the ``FrameProducer`` protocol and what its implementations share.

The UVC device asks its producer for the sizes and frame intervals to advertise, programs it on commit, reads
exposure and gain through it, and takes frames by index with the device time each is read out by (for pacing
in real time). The emulated camera's producer is ``FirmwareProducer`` (``firmware_producer``), over the one
``FirmwareCamera`` every other transport reads; tests and benchmarks stand small fakes behind the same protocol.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from rollcam.common.errors import ConfigError
from rollcam.sim.frame import Frame
from rollcam.sim.hwconfig import SensorConfig
from rollcam.sim.synthetic import resolve_settings

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
