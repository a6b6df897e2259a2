"""``FrameProducer`` over the firmware camera: the UVC function streams what ``FirmwareCamera`` schedules.

This is how ``rollcam emulate --usbip`` and the pyusb backend expose the same device the serial line, the
V4L2-like API and HTTP talk to: UVC's commit programs the firmware's mode and frame length and starts its
stream; UVC exposure requests write the firmware's exposure control and gain requests (hundredths) its linear
total gain (so its registers follow); frames are
the firmware's frames by sequence number, due when the firmware's schedule reads out their last line. UVC
offers YUYV, NV12 and MJPEG only, so a firmware camera left in a raw format streams its preview-ISP picture.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from rollcam.common.errors import ConfigError, DeviceError
from rollcam.firmware.camera import FirmwareCamera, FramePlan
from rollcam.firmware.pixfmt import is_raw
from rollcam.firmware.scheduler import FrameSchedule
from rollcam.sim.codecs import Levels, preview_frame
from rollcam.sim.frame import Frame
from rollcam.sim.synthetic import DEFAULT_EXPOSURE_NS

from .producer import CONTROLS, FPS_CHOICES, ControlRange, offered_intervals_ns


class FirmwareProducer:
    """Adapts a ``FirmwareCamera`` to the UVC function's ``FrameProducer`` protocol.

    UVC frame index ``i`` is firmware sequence ``base + i``, where ``base`` is the firmware's next sequence
    number when the host committed (sequence numbers keep counting across streams, as the firmware's do).
    """

    def __init__(self, camera: FirmwareCamera, fps_choices: Sequence[float] = FPS_CHOICES) -> None:
        self.camera = camera
        self.name = camera.sensor.name
        self._fps = tuple(fps_choices)
        self._base = camera.next_seq

    def __repr__(self) -> str:
        return f"FirmwareProducer({self.camera!r})"

    def sizes(self) -> list[tuple[int, int]]:
        current = self.camera.size
        return [current, *(s for s in self.camera.sizes() if s != current)]

    def intervals_ns(self, width: int, height: int) -> list[int]:
        return offered_intervals_ns(self.camera.sensor, width, height, self._fps, self.camera.spec.shutter)

    def configure(self, width: int, height: int, interval_ns: int) -> None:
        cam = self.camera
        if (width, height) not in self.sizes():  # what the descriptors offered: the modes and the current size
            raise DeviceError(f"{self.name}: size {width}x{height} is not one of {self.sizes()}")
        cam.stream_off()
        try:
            cam.set_size(width, height)
            cam.set_frame_interval_ns(int(interval_ns))
        except ConfigError as exc:
            raise DeviceError(f"{self.name}: cannot program {width}x{height} at {interval_ns} ns: {exc}") from None
        self._base = cam.next_seq
        cam.stream_on()  # renders once before the clock starts (compiled kernels, static layers): no opening drops

    def _schedule(self) -> FrameSchedule:
        sched = self.camera.current_schedule()
        if sched is None:
            raise DeviceError(f"{self.name}: the firmware camera is not streaming (no UVC commit yet, or stopped "
                              "over another interface)")
        return sched

    def frame_due_ns(self, index: int) -> int:
        return self._schedule().frame_due_ns(self._base + index)

    def frame(self, index: int) -> Frame:
        seq = self._base + index
        plan = FramePlan(seq, self._schedule())
        self.camera.note_made(seq)  # a later timing change re-anchors after this frame, not at the commit
        frame = self.camera.render(plan)  # a processed format's frame is the BGR picture UVC encodes
        if is_raw(frame.format):
            frame = dataclasses.replace(frame, data=preview_frame(frame, Levels.of_sensor(self.camera.sensor)),
                                        format="BGR3")
        return frame

    def now_ns(self) -> int:
        return self.camera.clock_ns()

    def _line_ns(self) -> int:
        return max(int(self.camera.spec.settings.timing.line_offset_ns(1)), 1)

    def control_range(self, name: str) -> ControlRange:
        s = self.camera.state
        if name == "exposure_ns":
            lo, hi = s.exposure_range()
            t = self.camera.spec.settings.timing
            default = min(max(round(DEFAULT_EXPOSURE_NS / self._line_ns()), lo), hi)  # the spec's own default
            return ControlRange(*(int(t.line_offset_ns(n)) for n in (lo, hi, default)), self._line_ns())
        if name == "gain":
            # UVC's PU gain is hundredths of the spec's linear total gain (analog x digital).
            g = s.sensor.gain
            lo, hi = round(g.analog_min * g.digital_min * 100), round(g.analog_max * g.digital_max * 100)
            return ControlRange(lo, hi, min(max(lo, 100), hi))
        raise DeviceError(f"control {name!r} is not one of {CONTROLS}")

    def get_control(self, name: str) -> int:
        self.control_range(name)
        if name == "gain":
            return round(self.camera.spec.gain * 100)
        return self.camera.spec.settings.exposure_ns

    def set_control(self, name: str, value: int) -> int:
        r = self.control_range(name)
        value = min(max(int(value), r.minimum), r.maximum)
        if name == "gain":
            self.camera.update(gain=value / 100)
        else:
            t = self.camera.spec.settings.timing
            self.camera.set_control("exposure", round(value * t.pixel_rate_hz / (t.line_length_pck * 1_000_000_000)))
        return self.get_control(name)
