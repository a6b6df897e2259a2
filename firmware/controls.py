"""The sensor's programmable state and its controls (V4L2 names and units) as a table of small functions.

``SensorState`` holds what the sensor is programmed with. ``CONTROLS`` lists each control's range function,
getter and setter; the setters carry the side effects a real driver has (VBLANK sets the frame length and
so the frame rate and the exposure range; flips are refused while streaming). Integer values outside the
range are clamped, as the V4L2 control framework does; a bad menu entry or boolean is an error.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

from rollcam.common.errors import ConfigError, DeviceError
from rollcam.sim.hwconfig import SensorConfig
from rollcam.sim.noise import split_gain
from rollcam.sim.sensor import flipped_cfa
from rollcam.sim.timing import LineTiming

from .spec import CameraSpec
from .traits import SensorTraits, traits_for

MAX_FRAME_LENGTH = 0xFFFF  # 16-bit frame length registers


@dataclass
class SensorState:
    """A working copy of a spec's programming in the sensor's own units (lines, pixel clocks, gain codes).

    Controls and registers edit it with the clamping a driver has; ``to_spec`` makes the new ``CameraSpec``.
    Gain codes are a view of the spec's linear total gain (split analog first, as ``SensorPipeline`` does):
    writing a code sets the total gain to the product of the two codes' gains.
    """

    spec: CameraSpec
    traits: SensorTraits
    frame_length_lines: int
    line_length_pck: int
    exposure_lines: int
    analog_code: int
    digital_code: int
    hflip: bool = False
    vflip: bool = False
    test_pattern: str = "none"
    streaming: bool = False

    @classmethod
    def of(cls, spec: CameraSpec, streaming: bool = False) -> SensorState:
        """The working copy of ``spec``."""
        traits = traits_for(spec.sensor.name)
        t, g = spec.settings.timing, spec.sensor.gain
        a, d, _ = split_gain(spec.gain, (g.analog_min, g.analog_max), (g.digital_min, g.digital_max))
        state = cls(spec, traits, t.frame_length_lines, t.line_length_pck, _lines_of(spec), 0, 0, spec.hflip,
                    spec.vflip, spec.test_pattern, streaming)
        state.analog_code = _clamp(traits.analog.to_code(a), *state.gain_range("analog"))
        state.digital_code = _clamp(traits.digital.to_code(d), *state.gain_range("digital"))
        return state

    def to_spec(self) -> CameraSpec:
        """The spec this state programs (validated); fields left as they were keep the spec's own values."""
        spec, before = self.spec, SensorState.of(self.spec)
        changes: dict = {"hflip": self.hflip, "vflip": self.vflip, "test_pattern": self.test_pattern}
        timing_changed = (self.frame_length_lines, self.line_length_pck) != (before.frame_length_lines,
                                                                           before.line_length_pck)
        if timing_changed:
            changes.update(frame_length_lines=self.frame_length_lines, line_length_pck=self.line_length_pck)
        if timing_changed or self.exposure_lines != before.exposure_lines:
            # Pinned in whole lines of the new timing: round(ns / line) gives these lines back.
            changes["exposure_ns"] = self.exposure_lines * max(int(self.timing.line_offset_ns(1)), 1)
        if (self.analog_code, self.digital_code) != (before.analog_code, before.digital_code):
            changes["gain"] = self.traits.analog.to_gain(self.analog_code) * self.traits.digital.to_gain(
                self.digital_code)
        return dataclasses.replace(spec, **changes)

    @property
    def sensor(self) -> SensorConfig:
        """The sensor description."""
        return self.spec.sensor

    @property
    def width(self) -> int:
        """Output width."""
        return self.spec.settings.width

    @property
    def height(self) -> int:
        """Output height."""
        return self.spec.settings.height

    @property
    def shutter(self) -> str:
        """``rolling`` or ``global``."""
        return self.spec.settings.shutter

    @property
    def pixel_rate_hz(self) -> int:
        """Pixel clock of the output's timing (a rescaled readout scales it)."""
        return self.spec.settings.timing.pixel_rate_hz

    @property
    def n_lines(self) -> int:
        """Lines read per frame."""
        return self.spec.settings.n_lines

    @property
    def timing(self) -> LineTiming:
        """Line timing as programmed."""
        return LineTiming(self.pixel_rate_hz, self.line_length_pck, self.frame_length_lines)

    @property
    def min_frame_length(self) -> int:
        """Shortest frame length the mode allows (its default one when that has less blanking)."""
        default = dataclasses.replace(self.spec, frame_length_lines=None, line_length_pck=None)
        return min(default.settings.timing.frame_length_lines,
                   self.n_lines + max(self.sensor.exposure.max_margin_lines, 1))

    def exposure_range(self) -> tuple[int, int]:
        """Exposure limits in lines for the current frame length (as ``resolve_settings`` clamps)."""
        e = self.sensor.exposure
        return e.min_lines, min(max(self.frame_length_lines - e.max_margin_lines, e.min_lines),
                                self.frame_length_lines)

    def gain_range(self, which: str) -> tuple[int, int]:
        """Code range of the ``analog`` or ``digital`` gain."""
        codec = getattr(self.traits, which)
        g = self.sensor.gain
        lo, hi = getattr(g, f"{which}_min"), getattr(g, f"{which}_max")
        return codec.to_code(lo), codec.to_code(hi)

    @property
    def gain(self) -> float:
        """Total linear gain the codes give (analog times digital)."""
        return self.traits.analog.to_gain(self.analog_code) * self.traits.digital.to_gain(self.digital_code)

    @property
    def bayer_order(self) -> str:
        """The Bayer order the output has with the current flips (a mirror swaps columns, a flip rows)."""
        return flipped_cfa(self.sensor.bayer_order, (self.width, self.height), self.hflip, self.vflip)

    def set_frame_length(self, lines: int) -> int:
        """Program the frame length (clamped), keeping the exposure within its new range."""
        self.frame_length_lines = _clamp(lines, self.min_frame_length, MAX_FRAME_LENGTH)
        lo, hi = self.exposure_range()
        self.exposure_lines = _clamp(self.exposure_lines, lo, hi)
        return self.frame_length_lines

    def set_exposure(self, lines: int) -> int:
        """Program the exposure in lines, clamped to what the frame length allows."""
        self.exposure_lines = _clamp(lines, *self.exposure_range())
        return self.exposure_lines

    def set_flip(self, axis: str, on: bool) -> bool:
        """Set ``hflip`` or ``vflip``; refused while streaming because it changes the Bayer order."""
        if self.streaming and getattr(self, axis) != bool(on):
            raise DeviceError(f"{axis} cannot change while streaming (it changes the Bayer order); stop first")
        setattr(self, axis, bool(on))
        return bool(on)

    def set_test_pattern(self, name: str) -> str:
        """Select a test pattern by name (``none`` shows the scene)."""
        if name not in self.traits.test_pattern_codes:
            raise ConfigError(f"test pattern {name!r} is not one of {list(self.traits.test_pattern_codes)}")
        self.test_pattern = name
        return name


def _lines_of(spec: CameraSpec) -> int:
    """The spec's realised exposure in whole lines."""
    t = spec.settings.timing
    return max(round(spec.settings.exposure_ns * t.pixel_rate_hz / (t.line_length_pck * 1_000_000_000)), 1)


def _clamp(value: int, lo: int, hi: int) -> int:
    return max(lo, min(hi, int(value)))


@dataclass(frozen=True)
class Control:
    """One control: kind (int, bool, menu), unit, range, getter and setter (None: read-only)."""

    name: str
    kind: str
    unit: str
    limits: Callable[[SensorState], tuple[int, int]]
    get: Callable[[SensorState], int]
    set: Callable[[SensorState, int], object] | None
    menu: Callable[[SensorState], list[str]] | None = None


def _menu(s: SensorState) -> list[str]:
    return list(s.traits.test_pattern_codes)


def _set_menu(s: SensorState, index: int) -> str:
    items = _menu(s)
    if not 0 <= int(index) < len(items):
        raise ConfigError(f"test_pattern index {index!r} is not in 0..{len(items) - 1} ({items})")
    return s.set_test_pattern(items[int(index)])


def _flip_control(axis: str) -> Control:
    def set_(s: SensorState, v: int) -> bool:
        if getattr(s.traits, f"{axis}_bit") is None:
            raise DeviceError(f"sensor {s.sensor.name!r} has no {axis}")
        return s.set_flip(axis, bool(v))

    return Control(axis, "bool", "", lambda s: (0, 1), lambda s: int(getattr(s, axis)), set_)


CONTROLS: dict[str, Control] = {c.name: c for c in (
    Control("exposure", "int", "lines", SensorState.exposure_range, lambda s: s.exposure_lines,
            SensorState.set_exposure),
    Control("analogue_gain", "int", "code", lambda s: s.gain_range("analog"), lambda s: s.analog_code,
            lambda s, v: setattr(s, "analog_code", _clamp(v, *s.gain_range("analog")))),
    Control("digital_gain", "int", "code", lambda s: s.gain_range("digital"), lambda s: s.digital_code,
            lambda s, v: setattr(s, "digital_code", _clamp(v, *s.gain_range("digital")))),
    Control("vblank", "int", "lines", lambda s: (s.min_frame_length - s.n_lines, MAX_FRAME_LENGTH - s.n_lines),
            lambda s: s.frame_length_lines - s.n_lines, lambda s, v: s.set_frame_length(s.n_lines + int(v))),
    Control("hblank", "int", "pixel clocks", lambda s: (s.line_length_pck - s.width,) * 2,
            lambda s: s.line_length_pck - s.width, None),
    Control("pixel_rate", "int", "Hz", lambda s: (s.pixel_rate_hz,) * 2, lambda s: s.pixel_rate_hz, None),
    Control("test_pattern", "menu", "", lambda s: (0, len(_menu(s)) - 1),
            lambda s: _menu(s).index(s.test_pattern), _set_menu, _menu),
    _flip_control("hflip"),
    _flip_control("vflip"),
)}
"""The controls every firmware camera offers, by V4L2-style name (V4L2_CID_<NAME upper>)."""


def describe(state: SensorState) -> dict[str, dict[str, object]]:
    """Every control with its kind, unit, range, current value and menu items (VIDIOC_QUERYCTRL's content)."""
    out = {}
    for name, c in CONTROLS.items():
        lo, hi = c.limits(state)
        out[name] = {"kind": c.kind, "unit": c.unit, "min": lo, "max": hi, "value": c.get(state),
                     "read_only": c.set is None, "menu": c.menu(state) if c.menu else None}
    return out


def line_ns(state: SensorState) -> int:
    """One line of the programmed timing in whole ns (at least 1)."""
    return max(int(state.timing.line_offset_ns(1)), 1)


def frame_duration_range_ns(state: SensorState) -> tuple[int, int]:
    """Shortest and longest frame period the mode allows (frame length limits times the line)."""
    t = state.timing
    return (int(LineTiming(t.pixel_rate_hz, t.line_length_pck, state.min_frame_length).frame_period_ns),
            int(LineTiming(t.pixel_rate_hz, t.line_length_pck, MAX_FRAME_LENGTH).frame_period_ns))


def program_exposure(state: SensorState, exposure_ns: int, frame_ns: tuple[int, int]) -> None:
    """Program an exposure in ns within a frame-period range in ns, as a camera's exposure control does: the
    frame is the shortest in the range that holds the exposure (plus the sensor's margin), and the exposure
    is then clamped to what that frame allows. Both are whole lines (rounded to the nearest)."""
    line = line_ns(state)
    lines = max(round(int(exposure_ns) / line), 1)
    lo, hi = (max(round(int(ns) / line), 1) for ns in frame_ns)
    state.set_frame_length(min(max(lines + state.sensor.exposure.max_margin_lines, lo), max(hi, lo)))
    state.set_exposure(lines)


def set_linear_gain(state: SensorState, which: str, gain: float) -> float:
    """Set the ``analog`` or ``digital`` gain to the code nearest a linear ``gain`` (clamped); returns the gain
    in effect."""
    codec = getattr(state.traits, which)
    code = _clamp(codec.to_code(max(float(gain), 1e-6)), *state.gain_range(which))
    setattr(state, f"{which}_code", code)
    return codec.to_gain(code)


def linear_gain(state: SensorState, which: str) -> float:
    """The ``analog`` or ``digital`` gain the current code gives, linear."""
    return getattr(state.traits, which).to_gain(getattr(state, f"{which}_code"))


def vblank_for_interval(spec: CameraSpec, interval_ns: int) -> int:
    """The vertical blanking (lines) whose frame length is nearest a frame period of ``interval_ns``."""
    t = spec.settings.timing
    lines = round(interval_ns * t.pixel_rate_hz / (t.line_length_pck * 1_000_000_000))
    return lines - spec.settings.n_lines


def get_control(state: SensorState, name: str) -> int:
    """Current value of control ``name``."""
    return _control(name).get(state)


def set_control(state: SensorState, name: str, value: int) -> int:
    """Set control ``name`` (integers clamped to range); returns the value now in effect."""
    ctrl = _control(name)
    if ctrl.set is None:
        raise DeviceError(f"control {name!r} is read-only")
    if isinstance(value, bool) or not isinstance(value, int):
        raise ConfigError(f"control {name!r} takes an integer, got {value!r}")
    if ctrl.kind == "bool" and value not in (0, 1):
        raise ConfigError(f"control {name!r} is a boolean (0 or 1), got {value!r}")
    ctrl.set(state, value)
    return ctrl.get(state)


def _control(name: str) -> Control:
    try:
        return CONTROLS[name]
    except KeyError:
        raise ConfigError(f"no control {name!r}; controls: {list(CONTROLS)}") from None
