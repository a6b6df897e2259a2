"""The firmware camera: the one device object every transport (V4L2, serial, HTTP, UVC) sits on.

``FirmwareCamera`` joins a sensor's programmable state (``controls``), its register map (``registers``), a
frame schedule in device time (``scheduler``) and a ``SyntheticCamera`` that makes the pixels. It is passive
and thread-safe: a transport asks ``plan_next()`` which frame is due next and when, waits until then on its
own clock, and calls ``render(plan)``. The device clock is the host clock passed in minus the boot time, in
integer ns.
"""

from __future__ import annotations

import collections
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rollcam.common.errors import ConfigError, DeviceError
from rollcam.sim import formats as sf
from rollcam.sim.frame import Frame
from rollcam.sim.hwconfig import SensorConfig, load_sensor
from rollcam.sim.synthetic import DEFAULT_EXPOSURE_NS, SHUTTERS

from . import controls as ctl
from .imaging import Imager
from .pixfmt import FORMATS, raw_formats
from .registers import RegisterFile
from .scene import build_scene
from .scheduler import FrameSchedule
from .traits import traits_for

FIRMWARE_VERSION = "1.0.0"
Clock = Callable[[], int]
"""A monotonic host clock in integer ns (``time.monotonic_ns`` by default; tests pass their own)."""


@dataclass(frozen=True)
class FramePlan:
    """The next frame to make: its sequence number and the schedule that says when its lines are due."""

    seq: int
    schedule: FrameSchedule

    @property
    def start_ns(self) -> int:
        """Start of exposure of the first line (device clock)."""
        return self.schedule.start_ns(self.seq)

    @property
    def due_ns(self) -> int:
        """Time the frame is complete (its last line read out)."""
        return self.schedule.frame_due_ns(self.seq)


class FirmwareCamera:
    """An emulated camera: controls and registers, stream state, trigger, device clock and frame production."""

    def __init__(self, sensor: SensorConfig | str, *, scene: dict[str, Any] | None = None,
                 size: tuple[int, int] | None = None, fps: float | None = None, shutter: str | None = None,
                 exposure_ns: int | None = None, gain: float = 1.0, clock: Clock | None = None,
                 serial_number: str = "0001", pixel_format: str | None = None, blur_px: float = 0.0) -> None:
        self.sensor = load_sensor(sensor) if isinstance(sensor, str) else sensor
        self.traits = traits_for(self.sensor.name)
        self.clock = clock or time.monotonic_ns
        self.boot_ns = self.clock()
        self.serial_number = serial_number
        self.lock = threading.RLock()
        self.changed = threading.Condition(self.lock)
        self.scene_options: dict[str, Any] = dict(scene or {"scene": "street"})
        mode = self.sensor.mode(None if size is None else f"{size[0]}x{size[1]}")
        t = self.sensor.timing(mode)
        shutter = shutter or self.sensor.shutter
        if shutter not in SHUTTERS:
            raise ConfigError(f"shutter {shutter!r} is not one of {SHUTTERS}")
        self.state = ctl.SensorState(self.sensor, self.traits, mode, t.frame_length_lines, t.line_length_pck, 1,
                                     0, 0, shutter)
        if fps is not None:
            if not (isinstance(fps, (int, float)) and 0 < fps < float("inf")):
                raise ConfigError(f"fps must be a positive finite number, got {fps!r}")
            self.state.set_frame_length(round(self.state.pixel_rate_hz / (fps * t.line_length_pck)))
        want_ns = DEFAULT_EXPOSURE_NS if exposure_ns is None else exposure_ns
        self.state.set_exposure(round(want_ns / max(t.line_offset_ns(1), 1)))
        self.state.analog_code = ctl._clamp(self.traits.analog.to_code(max(gain, 1e-6)),
                                            *self.state.gain_range("analog"))
        self.state.digital_code = ctl._clamp(self.traits.digital.to_code(1.0), *self.state.gain_range("digital"))
        self.registers = RegisterFile(self.state, self._mode_select)
        self.trigger_mode = "free"
        self._triggers: collections.deque[int] = collections.deque()
        self._schedule: FrameSchedule | None = None
        self._next_seq = 0
        self.imager = Imager(self.sensor, serial=serial_number, blur_px=_blur(blur_px))
        self._format = "YUYV"  # processed fourcc, or a raw one as the sensor lists it (before flips)
        if pixel_format is not None:
            self.set_format(pixel_format)
        self.stats = {"frames": 0, "skipped": 0, "triggers": 0}
        build_scene(self.scene_options, mode.width, mode.height)  # validate now, not at the first frame

    def __repr__(self) -> str:
        s = self.state
        return (f"FirmwareCamera({self.sensor.name!r}, {s.mode.width}x{s.mode.height}, {s.timing.fps:.2f} fps, "
                f"{s.shutter}, {'streaming' if s.streaming else 'idle'}, next seq {self._next_seq})")

    # -------------------------------------------------------------------------------------- identity, clock
    def identity(self) -> str:
        """The SCPI ``*IDN?`` answer: maker, model, serial number, firmware version."""
        return f"rollcam,{self.sensor.name.upper()}-EMU,{self.serial_number},{FIRMWARE_VERSION}"

    def clock_ns(self) -> int:
        """Device clock: integer ns since the device booted."""
        return self.clock() - self.boot_ns

    def host_ns(self, device_ns: int) -> int:
        """The host clock reading of a device time (for pacing)."""
        return device_ns + self.boot_ns

    # ---------------------------------------------------------------------------------------- format
    @property
    def size(self) -> tuple[int, int]:
        """Output width and height of the current mode."""
        return self.state.mode.width, self.state.mode.height

    def sizes(self) -> list[tuple[int, int]]:
        """Output sizes of the sensor's modes."""
        return [(m.width, m.height) for m in self.sensor.modes]

    @property
    def formats(self) -> list[str]:
        """Fourccs the camera streams: the ISP's processed ones, then the sensor's raw ones in the Bayer order
        the current flips give (as a Linux sensor driver enumerates them)."""
        with self.lock:
            return [*FORMATS, *(self._flipped(f) for f in raw_formats(self.sensor))]

    @property
    def pixel_format(self) -> str:
        """The current format's fourcc; a raw one follows the flips (RG10 with HFLIP is BA10)."""
        with self.lock:
            return self._flipped(self._format)

    def _flipped(self, fourcc: str) -> str:
        f = sf.FORMATS.get(fourcc)
        if fourcc in FORMATS or f is None or f.cfa == "mono":
            return fourcc
        return sf.bayer_fourcc(self.state.bayer_order, f.bits, f.packing == "csi2")

    def _unflipped(self, fourcc: str) -> str:
        """The processed or sensor-listed raw fourcc a request means (raw: either Bayer order's name)."""
        want = fourcc.ljust(4) if len(fourcc) == 3 else fourcc
        if want in FORMATS:
            return want
        for base in raw_formats(self.sensor):
            if want in (base, self._flipped(base)):
                return base
        raise ConfigError(f"pixel format {fourcc!r} is not one of this {self.sensor.name} camera's "
                          f"{self.formats}")

    def resolve_format(self, fourcc: str) -> str:
        """The fourcc ``set_format(fourcc)`` would give (a raw one in the current Bayer order); ConfigError if
        the camera has no such format."""
        with self.lock:
            return self._flipped(self._unflipped(fourcc))

    def set_format(self, fourcc: str) -> str:
        """Select the output format (processed, or raw: sensor samples without the ISP); refused while
        streaming, as a driver refuses S_FMT on a busy queue. Returns the fourcc in effect."""
        with self.changed:
            base = self._unflipped(fourcc)
            if self.state.streaming and base != self._format:
                raise DeviceError(f"cannot change the format to {fourcc!r} while streaming; stop first")
            self._format = base
            self.changed.notify_all()
            return self._flipped(base)

    @property
    def raw(self) -> bool:
        """True when the current format is raw sensor samples (frames carry them instead of a BGR render)."""
        return self._format not in FORMATS

    @property
    def blur_px(self) -> float:
        """Motion-blur bound of raw frames in pixels (0: each line sampled at mid-exposure, the real-time default)."""
        return self.imager.blur_px

    def set_blur_px(self, blur_px: float) -> None:
        """Integrate raw frames over each line's exposure with this blur bound (px); 0 turns it off."""
        with self.changed:
            self.imager.blur_px = _blur(blur_px)
            self.changed.notify_all()

    def set_size(self, width: int, height: int) -> None:
        """Switch to the mode of this output size (its default frame length); refused while streaming."""
        with self.lock:
            if self.state.streaming:
                raise DeviceError("cannot change the mode while streaming; stop first")
            mode = self.sensor.mode(f"{width}x{height}")
            s = self.state
            s.mode, s.line_length_pck = mode, mode.line_length_pck
            s.set_frame_length(mode.frame_length_lines)
            s.set_exposure(s.exposure_lines)

    @property
    def frame_interval_ns(self) -> int:
        """Frame period as programmed (whole ns, rounded down)."""
        return self.state.timing.frame_period_ns

    def set_frame_interval_ns(self, interval_ns: int) -> int:
        """Program the frame length nearest ``interval_ns`` (within the mode's limits); returns the new interval."""
        with self.lock:
            s = self.state
            lines = round(interval_ns * s.pixel_rate_hz / (s.line_length_pck * 1_000_000_000))
        self.set_control("vblank", lines - s.mode.height)
        return self.frame_interval_ns

    # ---------------------------------------------------------------------------------------- controls
    def controls(self) -> dict[str, dict[str, Any]]:
        """Every control with its kind, unit, range, current value and menu items."""
        with self.lock:
            out = {}
            for name, c in ctl.CONTROLS.items():
                lo, hi = c.limits(self.state)
                out[name] = {"kind": c.kind, "unit": c.unit, "min": lo, "max": hi, "value": c.get(self.state),
                             "read_only": c.set is None, "menu": c.menu(self.state) if c.menu else None}
            return out

    def get_control(self, name: str) -> int:
        """Current value of a control."""
        with self.lock:
            return ctl.get_control(self.state, name)

    def set_control(self, name: str, value: int) -> int:
        """Set a control (integers clamped to range); returns the value in effect; takes effect next frame."""
        with self.changed:
            value = ctl.set_control(self.state, name, value)
            self.changed.notify_all()
            return value

    def read_register(self, key: str | int) -> int:
        """Read a register by address or name."""
        with self.lock:
            return self.registers.read(key)

    def write_register(self, key: str | int, value: int) -> int:
        """Write a register (with its effect); returns its new value."""
        with self.changed:
            value = self.registers.write(key, value)
            self.changed.notify_all()
            return value

    def set_shutter(self, shutter: str) -> None:
        """Switch global/rolling shutter, where the sensor has both; refused while streaming."""
        with self.lock:
            if shutter not in SHUTTERS:
                raise ConfigError(f"shutter {shutter!r} is not one of {SHUTTERS}")
            if shutter != self.state.shutter and not self.traits.dual_shutter:
                raise DeviceError(f"sensor {self.sensor.name!r} has only a {self.sensor.shutter} shutter")
            if self.state.streaming and shutter != self.state.shutter:
                raise DeviceError("cannot change the shutter while streaming; stop first")
            self.state.shutter = shutter

    def set_scene(self, **changes: Any) -> None:
        """Change scene options (``scene``, ``seed`` and the kind's own); applies from the next frame."""
        with self.changed:
            options = dict(self.scene_options)
            if "scene" in changes and changes["scene"] != options.get("scene"):
                options = {"seed": options.get("seed", 0)}  # another kind: its own defaults
            options.update(changes)
            build_scene(options, *self.size)
            self.scene_options = options
            self.changed.notify_all()

    # ---------------------------------------------------------------------------------------- streaming
    @property
    def streaming(self) -> bool:
        """True between stream_on and stream_off."""
        return self.state.streaming

    @property
    def next_seq(self) -> int:
        """Sequence number the next planned frame gets (it counts across stream starts)."""
        return self._next_seq

    def _mode_select(self, on: bool) -> None:
        (self.stream_on if on else self.stream_off)()

    def stream_on(self) -> None:
        """Start streaming: frame ``next seq`` starts exposing now (device clock). Idempotent."""
        with self.changed:
            if not self.state.streaming:
                # built before the clock starts
                self.imager.camera(self.state, self.scene_options, self._format if self.raw else None)
                self.state.streaming = True
                self._schedule = self._new_schedule(self.clock_ns(), self._next_seq)
                self.changed.notify_all()

    def stream_off(self) -> None:
        """Stop streaming; frames not yet planned are never made. Idempotent."""
        with self.changed:
            self.state.streaming = False
            self._triggers.clear()
            self.changed.notify_all()

    def set_trigger_mode(self, mode: str) -> None:
        """``free`` (frames back to back) or ``external`` (one frame per ``trigger()``)."""
        if mode not in ("free", "external"):
            raise ConfigError(f"trigger mode {mode!r} is not 'free' or 'external'")
        with self.changed:
            self.trigger_mode = mode
            self._triggers.clear()
            if self.state.streaming:
                self._schedule = self._new_schedule(self.clock_ns(), self._next_seq)
            self.changed.notify_all()

    def trigger(self) -> int:
        """Start one frame now (external trigger mode, streaming); returns its exposure start (device ns)."""
        with self.changed:
            if self.trigger_mode != "external":
                raise DeviceError("trigger needs trigger mode 'external' (TRIGMODE EXTERNAL)")
            if not self.state.streaming:
                raise DeviceError("trigger while not streaming (STREAM ON first)")
            t = self.clock_ns()
            self._triggers.append(t)
            self.stats["triggers"] += 1
            self.changed.notify_all()
            return t

    def _new_schedule(self, epoch_ns: int, first_seq: int) -> FrameSchedule:
        s = self.state
        exposure_ns = int(s.timing.line_offset_ns(s.exposure_lines))
        n_lines = s.mode.width if self.sensor.readout.by_column else s.mode.height
        return FrameSchedule(s.timing, epoch_ns, first_seq, exposure_ns, n_lines, s.shutter == "rolling")

    def current_schedule(self) -> FrameSchedule | None:
        """The schedule frames follow from the next one on (timing changes included), or None when idle."""
        with self.lock:
            if not self.state.streaming or self._schedule is None:
                return None
            sched = self._schedule
            fresh = self._new_schedule(sched.start_ns(self._next_seq), self._next_seq)
            if (fresh.timing, fresh.exposure_ns, fresh.rolling) != (sched.timing, sched.exposure_ns, sched.rolling):
                sched = self._schedule = fresh
            return sched

    def plan_next(self, now_ns: int | None = None) -> FramePlan | None:
        """The next frame to make, or None (not streaming, or waiting for a trigger).

        Timing changes take effect from the next frame. With ``now_ns`` (device clock), a free-running stream
        skips the frames whose readout already ended before ``now_ns`` (counted in ``stats['skipped']``).
        """
        with self.lock:
            if not self.state.streaming or self._schedule is None:
                return None
            seq = self._next_seq
            if self.trigger_mode == "external":
                if not self._triggers:
                    return None
                sched = self._new_schedule(self._triggers.popleft(), seq)
            else:
                sched = self.current_schedule()
                assert sched is not None
                if now_ns is not None:
                    late = sched.first_due_from(seq, now_ns)
                    self.stats["skipped"] += late - seq
                    seq = late
            self._next_seq = seq + 1
            return FramePlan(seq, sched)

    def next_frame(self, now_ns: int | None = None) -> Frame | None:
        """Plan and render the next frame at once (no pacing); None when none is due (idle, or no trigger)."""
        plan = self.plan_next(now_ns)
        return None if plan is None else self.render(plan)

    def wait_changed(self, timeout_s: float) -> None:
        """Block until a control, the stream state or a trigger changes, or ``timeout_s`` passes."""
        with self.changed:
            self.changed.wait(timeout_s)

    # ---------------------------------------------------------------------------------------- pixels
    def note_made(self, seq: int) -> None:
        """Record that frame ``seq`` was planned by a consumer that does not use ``plan_next`` (UVC), so the
        next timing change re-anchors the schedule after it rather than at the stream's start."""
        with self.lock:
            self._next_seq = max(self._next_seq, seq + 1)

    def render(self, plan: FramePlan) -> Frame:
        """Make frame ``plan.seq``: the scene (or the test pattern) at its lines' device times, flips applied."""
        with self.lock:
            cam = self.imager.camera(self.state, self.scene_options, self._format if self.raw else None)
            look = (self.state.hflip, self.state.vflip, self.state.test_pattern, self.state.bayer_order)
            self.stats["frames"] += 1
        return self.imager.render(cam, plan, *look)


def _blur(blur_px: float) -> float:
    if not isinstance(blur_px, (int, float)) or not 0 <= blur_px < float("inf"):
        raise ConfigError(f"blur_px must be a finite number >= 0 (0: no motion blur), got {blur_px!r}")
    return float(blur_px)
