"""The firmware camera: the one device object every path to an emulated sensor reads frames from.

``FirmwareCamera`` holds the current ``CameraSpec`` (``spec``, replaced whole on every change) and the stream
state (``DeviceStream``: clock, stream on/off, trigger, frame plan). The in-process ``emu:`` source, V4L2,
serial, HTTP and UVC all program it and call ``render(plan)``; a transport asks ``plan_next()`` which frame
is due next and when, waits until then on its own clock, and renders it. Controls and registers are edited
on a ``SensorState`` working copy and committed as a new spec, so every door validates the same way.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from fractions import Fraction
from typing import Any

from rollcam.common.errors import ConfigError, DeviceError
from rollcam.sim.frame import Frame
from rollcam.sim.hwconfig import SensorConfig
from rollcam.sim.synthetic import SyntheticCamera, resolve_settings

from . import controls as ctl
from .imaging import Imager, warm, warm_ahead
from .insensor_stage import InSensorStage
from .options import SHUTTERS
from .registers import RegisterFile
from .spec import CameraSpec
from .stream import CameraStats, Clock, DeviceStream, FramePlan, schedule_of
from .traits import traits_for

FIRMWARE_VERSION = "1.0.0"
_IDLE_ONLY = ("size", "pixel_format", "shutter", "readout", "hflip", "vflip")
__all__ = ["CameraStats", "Clock", "FirmwareCamera", "FramePlan"]


class FirmwareCamera(DeviceStream):
    """An emulated camera: its spec, controls and registers, formats, and frame production."""

    def __init__(self, spec: CameraSpec | SensorConfig | str, *, clock: Clock | None = None,
                 serial_number: str | None = None, boot_ns: int | None = None, timebase: Any = None,
                 **fields: Any) -> None:
        if not isinstance(spec, CameraSpec):
            if serial_number is not None:
                fields["serial"] = serial_number
            spec = CameraSpec.create(spec, **fields)
        elif fields or serial_number is not None:
            raise ConfigError(f"give a CameraSpec or its fields, not both ({sorted(fields)})")
        super().__init__(clock, boot_ns)
        self.timebase = timebase
        """None, or a rig camera's clock (``rollcam.firmware.rig.RigTimebase``): frames are rendered at the world
        time of their device start and stamped on the device clock."""
        self.spec = spec
        self.sensor = spec.sensor
        self.traits = traits_for(self.sensor.name)
        self.registers = RegisterFile(self.sensor, self._mode_select)
        self.imager = Imager()
        self.insensor = InSensorStage()  # the in-sensor network's runs; ``insensor.ledger(spec)``: the ledger

    def __repr__(self) -> str:
        s = self.spec.settings
        return (f"FirmwareCamera({self.sensor.name!r}, {s.width}x{s.height}, {s.timing.fps:.2f} fps, {s.shutter}, "
                f"{self.pixel_format.strip()}, {'streaming' if self.streaming else 'idle'}, next seq {self.next_seq})")

    @property
    def serial_number(self) -> str:
        """The device's serial number (also the seed of its fixed-pattern noise)."""
        return self.spec.serial

    def identity(self) -> str:
        """The SCPI ``*IDN?`` answer: maker, model, serial number, firmware version."""
        return f"rollcam,{self.sensor.name.upper()}-EMU,{self.serial_number},{FIRMWARE_VERSION}"

    # -------------------------------------------------------------------------------------- the spec
    @property
    def state(self) -> ctl.SensorState:
        """A snapshot of the programming in the sensor's units (lines, codes, flips)."""
        with self.lock:
            return ctl.SensorState.of(self.spec, self.streaming)

    def reprogram(self, spec: CameraSpec, *, idle_only: str | None = None) -> CameraSpec:
        """Make ``spec`` the camera's programming from the next frame. ``idle_only`` names a change that a
        streaming device refuses (mode, format, shutter) when ``spec`` differs from the current one in it."""
        with self.changed:
            if spec.sensor is not self.sensor:
                raise ConfigError(f"a {spec.sensor.name} spec cannot program a {self.sensor.name} camera")
            if idle_only and self.streaming and spec != self.spec:
                raise DeviceError(f"cannot change the {idle_only} while streaming; stop first")
            if self.streaming:
                warm(spec)  # a new kind of frame compiles now, before its frame is due
            self._commit(spec)
            return spec

    def update(self, *, idle_only: str | None = None, **fields: Any) -> CameraSpec:
        """Replace fields of the spec (re-validated), as ``dataclasses.replace`` does."""
        if self.streaming:  # compile a new kind of frame before taking the lock the frames being made need
            warm_ahead(lambda: dataclasses.replace(self.spec, **fields))
        with self.lock:
            return self.reprogram(dataclasses.replace(self.spec, **fields), idle_only=idle_only)

    def set_options(self, options: Mapping[str, Any]) -> CameraSpec:
        """Change options by their text names (``rollcam.firmware.options``): ``scene``, ``seed``, ``gain``, ...;
        a change of size, format, shutter, readout or flips is refused while streaming. The new spec (and its
        scene) is built before the camera is locked, so a scene change never holds up the frames."""
        with self.lock:
            base = self.spec
        spec = base.with_options(options)  # builds a new scene off the lock: frames keep rendering meanwhile
        if self.streaming:  # and compiles a new kind of frame off it too
            warm_ahead(lambda: spec)
        with self.lock:
            if self.spec is not base:  # changed meanwhile: apply the options on top of that (scene cached now)
                spec = self.spec.with_options(options)
            moved = [f for f in _IDLE_ONLY if getattr(spec, f) != getattr(self.spec, f)]
            if self.streaming and moved:
                raise DeviceError(f"cannot change {moved} while streaming; stop first")
            return self.reprogram(spec)

    @property
    def scene_options(self) -> dict[str, Any]:
        """The scene: kind, seed and the options given (the rest are the option table's defaults)."""
        return self.spec.scene_values()

    # ---------------------------------------------------------------------------------------- format
    @property
    def size(self) -> tuple[int, int]:
        """Output width and height."""
        return self.spec.settings.width, self.spec.settings.height

    def sizes(self) -> list[tuple[int, int]]:
        """Output sizes of the sensor's modes."""
        return [(m.width, m.height) for m in self.sensor.modes]

    @property
    def formats(self) -> list[str]:
        """Fourccs the camera streams (``CameraSpec.device_formats``: processed, then raw in the flips' order)."""
        return self.spec.device_formats()

    @property
    def pixel_format(self) -> str:
        """The current format's fourcc; a raw one follows the flips (RG10 with HFLIP is GR10)."""
        return self.spec.output_format

    def resolve_format(self, fourcc: str) -> str:
        """The fourcc ``set_format(fourcc)`` would give (a raw one in the current Bayer order); ConfigError if
        the camera has no such format."""
        return self.spec.resolve_format(fourcc)

    def set_format(self, fourcc: str) -> str:
        """Select the output format (processed, or raw: sensor samples without the ISP); refused while
        streaming, as a driver refuses S_FMT on a busy queue. Returns the fourcc in effect."""
        with self.lock:
            return self.update(pixel_format=self.resolve_format(fourcc), idle_only="format").output_format

    @property
    def raw(self) -> bool:
        """True when the current format is raw sensor samples."""
        return self.spec.raw

    def set_size(self, width: int, height: int) -> None:
        """Switch to this output size (its default frame length); refused while streaming."""
        self.update(size=(width, height), frame_length_lines=None, line_length_pck=None, idle_only="mode")

    def set_shutter(self, shutter: str) -> None:
        """Switch global/rolling shutter, where the sensor has both; refused while streaming."""
        if shutter not in SHUTTERS:
            raise ConfigError(f"shutter {shutter!r} is not one of {SHUTTERS}")
        if shutter != self.spec.shutter and not self.traits.dual_shutter:
            raise DeviceError(f"sensor {self.sensor.name!r} has only a {self.sensor.shutter} shutter")
        self.update(shutter=shutter, idle_only="shutter")

    @property
    def frame_interval_ns(self) -> int:
        """Frame period as programmed (whole ns, rounded down)."""
        return self.spec.settings.timing.frame_period_ns

    def set_frame_interval_ns(self, interval_ns: int) -> int:
        """Program the frame length nearest ``interval_ns`` (within the mode's limits); returns the new interval."""
        with self.lock:
            self.set_control("vblank", ctl.vblank_for_interval(self.spec, interval_ns))
            return self.frame_interval_ns

    # ---------------------------------------------------------------------------------------- controls
    def controls(self) -> dict[str, dict[str, Any]]:
        """Every control with its kind, unit, range, current value and menu items."""
        return ctl.describe(self.state)

    def get_control(self, name: str) -> int:
        """Current value of a control."""
        return ctl.get_control(self.state, name)

    def set_control(self, name: str, value: int) -> int:
        """Set a control (integers clamped to range); returns the value in effect; takes effect next frame."""
        with self.lock:
            state = self.state
            value = ctl.set_control(state, name, value)
            self.reprogram(state.to_spec())
            return value

    def resettable_controls(self) -> dict[str, int]:
        """The writable controls' values now, frame length first: what ``reset_controls`` restores (flips
        excepted: they change the readout's Bayer order, which a stream cannot)."""
        c = self.controls()
        names = ["vblank", *(n for n in c if n != "vblank")]
        return {n: c[n]["value"] for n in names if n in c and not c[n]["read_only"] and n not in ("hflip", "vflip")}

    def reset_controls(self, values: Mapping[str, int]) -> None:
        """A sensor register reset under a running stream: the controls return to ``values``
        (``resettable_controls`` of the camera as it came up) from the next frame; counted in
        ``stats.register_resets``."""
        with self.lock:
            state = self.state
            for name, value in values.items():
                ctl.set_control(state, name, value)
            self.stats.register_resets += 1
            self.reprogram(state.to_spec())

    def read_register(self, key: str | int) -> int:
        """Read a register by address or name."""
        return self.registers.read(self.state, key)

    def write_register(self, key: str | int, value: int) -> int:
        """Write a register (with its effect); returns its new value."""
        with self.lock:
            state = self.state
            value = self.registers.write(state, key, value)  # a MODE_SELECT write starts or stops the stream
            self.reprogram(state.to_spec())
            return value

    def _mode_select(self, on: bool) -> None:
        (self.stream_on if on else self.stream_off)()

    # ---------------------------------------------------------------------------------------- pixels
    @property
    def synthetic(self) -> SyntheticCamera:
        """The SyntheticCamera that renders the current spec."""
        return self.imager.camera(self.spec)

    def _warm(self) -> None:  # at stream on, before the clock starts
        warm(self.spec, self.imager)

    def schedule(self, epoch_ns: int = 0, first_seq: int = 0) -> Any:
        """A schedule of the current spec from ``epoch_ns`` on, for reading frames without pacing."""
        return schedule_of(self.spec, epoch_ns, first_seq)

    def next_frame(self, now_ns: int | None = None) -> Frame | None:
        """Plan and render the next frame at once (no pacing); None when none is due (idle, or no trigger)."""
        plan = self.plan_next(now_ns)
        return None if plan is None else self.render(plan)

    def inject(self, tensor: Any) -> int:
        """Put an input tensor in the place of the next frame's on the in-sensor network (``InSensorStage.inject``);
        that frame is made even if the consumer is late for it. Returns its sequence number."""
        seq = self.insensor.inject(self.spec, tensor, self.next_seq)
        self.hold(seq)
        return seq

    def render(self, plan: FramePlan, shutter: str | None = None) -> Frame:
        """Frame ``plan.seq`` from the current spec (optionally under the other shutter): ``make``'s frame."""
        return self.make(plan, shutter)[1]

    def make(self, plan: FramePlan, shutter: str | None = None) -> tuple[CameraSpec, Frame]:
        """Frame ``plan.seq`` from the current spec at its lines' device times (optionally under the other shutter,
        for paired GS/RS data), flips applied, with the in-sensor results if any (``insensor``); and that spec."""
        spec = self._spec_for_frame()
        if self.timebase is None:
            return spec, self.insensor.make(spec, self.imager, plan.seq, plan.start_ns, shutter, self.stats)
        world = self.timebase.world_ns(plan.start_ns)
        frame = self.insensor.make(spec, self.imager, plan.seq, world, shutter, self.stats)
        return spec, self.timebase.stamp(frame, world, plan.start_ns)


def default_interval(spec: CameraSpec, width: int, height: int) -> Fraction:
    """The frame period of ``spec``'s sensor at an output size and its default frame length, in seconds as V4L2's
    fraction (a mode's own rate; a size no mode has reads out in its mode's time)."""
    t = resolve_settings(spec.sensor, size=(width, height), shutter=spec.shutter, readout=spec.readout).timing
    return Fraction(t.frame_period_pck, t.pixel_rate_hz)
