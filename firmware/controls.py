"""The sensor's programmable state and its controls (V4L2 names and units) as a table of small functions.

``SensorState`` holds what the sensor is programmed with. ``CONTROLS`` lists each control's range function,
getter and setter; the setters carry the side effects a real driver has (VBLANK sets the frame length and
so the frame rate and the exposure range; flips are refused while streaming). Integer values outside the
range are clamped, as the V4L2 control framework does; a bad menu entry or boolean is an error.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from rollcam.common.errors import ConfigError, DeviceError
from rollcam.sim.hwconfig import SensorConfig, SensorMode
from rollcam.sim.timing import LineTiming

from .traits import SensorTraits

MAX_FRAME_LENGTH = 0xFFFF  # 16-bit frame length registers


@dataclass
class SensorState:
    """The sensor's programmed values: mode, frame and line length, exposure lines, gain codes, flips."""

    sensor: SensorConfig
    traits: SensorTraits
    mode: SensorMode
    frame_length_lines: int
    line_length_pck: int
    exposure_lines: int
    analog_code: int
    digital_code: int
    shutter: str
    hflip: bool = False
    vflip: bool = False
    test_pattern: str = "none"
    streaming: bool = False

    @property
    def pixel_rate_hz(self) -> int:
        """Pixel clock of the current mode."""
        return self.mode.pixel_rate_hz or self.sensor.pixel_rate_hz

    @property
    def timing(self) -> LineTiming:
        """Line timing as programmed."""
        return LineTiming(self.pixel_rate_hz, self.line_length_pck, self.frame_length_lines)

    @property
    def min_frame_length(self) -> int:
        """Shortest frame length the mode allows (its configured one when that has less blanking)."""
        return min(self.mode.frame_length_lines, self.mode.height + max(self.sensor.exposure.max_margin_lines, 1))

    def exposure_range(self) -> tuple[int, int]:
        """Exposure limits in lines for the current frame length."""
        e = self.sensor.exposure
        return e.min_lines, max(self.frame_length_lines - e.max_margin_lines, e.min_lines)

    def gain_range(self, which: str) -> tuple[int, int]:
        """Code range of the ``analog`` or ``digital`` gain."""
        codec = getattr(self.traits, which)
        g = self.sensor.gain
        lo, hi = getattr(g, f"{which}_min"), getattr(g, f"{which}_max")
        return codec.to_code(lo), codec.to_code(hi)

    @property
    def gain(self) -> float:
        """Total linear gain (analog times digital)."""
        return self.traits.analog.to_gain(self.analog_code) * self.traits.digital.to_gain(self.digital_code)

    @property
    def bayer_order(self) -> str:
        """The Bayer order the output has with the current flips (a mirror swaps columns, a flip rows)."""
        order = self.sensor.bayer_order
        if order == "mono":
            return order
        if self.hflip:
            order = order[1] + order[0] + order[3] + order[2]
        if self.vflip:
            order = order[2:] + order[:2]
        return order

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
    Control("vblank", "int", "lines", lambda s: (s.min_frame_length - s.mode.height, MAX_FRAME_LENGTH - s.mode.height),
            lambda s: s.frame_length_lines - s.mode.height, lambda s, v: s.set_frame_length(s.mode.height + int(v))),
    Control("hblank", "int", "pixel clocks", lambda s: (s.line_length_pck - s.mode.width,) * 2,
            lambda s: s.line_length_pck - s.mode.width, None),
    Control("pixel_rate", "int", "Hz", lambda s: (s.pixel_rate_hz,) * 2, lambda s: s.pixel_rate_hz, None),
    Control("test_pattern", "menu", "", lambda s: (0, len(_menu(s)) - 1),
            lambda s: _menu(s).index(s.test_pattern), _set_menu, _menu),
    _flip_control("hflip"),
    _flip_control("vflip"),
)}
"""The controls every firmware camera offers, by V4L2-style name (V4L2_CID_<NAME upper>)."""


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
