"""Sensor descriptions: hw_configs/*.yaml loaded into frozen, validated ``SensorConfig`` objects.

Validation is table-driven (``rollcam.sim.configschema``): each field of a config class carries its schema
row and each class a ``_rules`` table of checks that relate several values. The loader turns YAML into objects
and rejects unknown and missing keys; each class's ``__post_init__`` runs its schema and rules, so objects
made with ``dataclasses.replace`` are checked too. Errors are ``ConfigError``s naming the file, the dotted key
(``modes[1].line_length_pck``), the expected form and the bad value. The optional ``imu`` section is
``rollcam.sim.imu.ImuParams``; the optional ``link`` section (``Link``) the sensor's CSI-2 or USB link.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import re
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, ClassVar

from rollcam.common.errors import ConfigError

from .configschema import (
    _Checked,
    _dotted,
    _f,
    _Invalid,
    _ListOf,
    _nonempty,
    _nonneg,
    _one_of,
    _parse_section,
    _pos,
    _Rule,
)
from .configschema import _schema as _schema  # re-exported: tests read a class's schema rows from here
from .formats import FORMATS
from .imu import ImuParams
from .timing import LineTiming, Readout
from .yamlsafe import read_yaml

_PACKAGE = "rollcam.hw_configs"

BAYER_ORDERS = ("RGGB", "BGGR", "GRBG", "GBRG", "mono")
REGISTER_ROLES = ("chip_id", "mode_select", "frame_length", "line_length", "exposure", "analog_gain",
                  "digital_gain", "orientation", "test_pattern")
FOURCCS: dict[str, tuple[str | None, int]] = {
    **{f: (None if f == "GREY" else p.cfa, p.bits) for f, p in FORMATS.items()},
    **dict.fromkeys(("UYVY", "XR24", "MJPG", "H264"), (None, 8)),
}
"""Known V4L2 fourccs -> (Bayer order, "mono", or None for processed formats; bits per sample).

GREY counts as processed: a mono sensor's 8-bit output and a colour ISP's luma alike."""


@dataclass(frozen=True)
class Crop(_Checked):
    """Sensor area a mode reads, in full-resolution active-pixel coordinates."""

    left: int = _f(int, "an integer >= 0 (pixels)", _nonneg)
    top: int = _f(int, "an integer >= 0 (pixels)", _nonneg)
    width: int = _f(int, "a positive integer (pixels)", _pos)
    height: int = _f(int, "a positive integer (pixels)", _pos)


@dataclass(frozen=True, kw_only=True)
class SensorMode(_Checked):
    """One readout mode: output size, line and frame length, optional binning, crop and own pixel rate."""

    name: str = _f(str, "a non-empty string", _nonempty)
    width: int = _f(int, "a positive integer (output pixels per line)", _pos)
    height: int = _f(int, "a positive integer (output lines)", _pos)
    line_length_pck: int = _f(int, "a positive integer (pixel clocks per line)", _pos)
    frame_length_lines: int = _f(int, "a positive integer (lines per frame)", _pos)
    binning: tuple[int, ...] = _f(_ListOf(int), "[horizontal, vertical], factors >= 1",
                                  lambda v: len(v) == 2 and min(v) >= 1, (1, 1))
    crop: Crop | None = _f(Crop, "a mapping {left, top, width, height}", None, None)  # noqa: RUF009
    pixel_rate_hz: int | None = _f(int, "a positive integer (Hz), overriding the sensor's", _pos, None)
    _rules: ClassVar[tuple[_Rule, ...]] = (
        _Rule("line_length_pck", lambda s, _, i: s.line_length_pck >= s.width,
              lambda s, _, i: f">= width ({s.width}): a line cannot be shorter than its active pixels"),
        _Rule("frame_length_lines", lambda s, _, i: s.frame_length_lines >= s.height,
              lambda s, _, i: f">= height ({s.height}): a frame cannot hold fewer lines than it outputs"),
        _Rule("crop", lambda s, _, i: s.crop is None or (s.crop.width, s.crop.height) == s.read_size,
              lambda s, _, i: "width x height = output size x binning = {}x{}".format(*s.read_size)),
    )

    @property
    def read_size(self) -> tuple[int, int]:
        """Width and height of the sensor area this mode reads (output size times binning)."""
        return self.width * self.binning[0], self.height * self.binning[1]


@dataclass(frozen=True, kw_only=True)
class Link(_Checked):
    """The sensor's data link to its host: MIPI CSI-2 (``lanes`` x ``lane_mbps``) or USB (``lane_mbps`` is the
    bus's signalling rate, ``lanes`` 1), for the bandwidth ledger (``rollcam.firmware.ledger``)."""

    bus: str = _f(str, "'csi2' or 'usb'", _one_of("csi2", "usb"))
    lanes: int = _f(int, "an integer in 1..8 (data lanes)", lambda v: 1 <= v <= 8)
    lane_mbps: float = _f(float, "a positive number (Mbit/s per lane)", _pos)

    @property
    def capacity_bps(self) -> int:
        """Raw bits per second the link carries, all lanes together."""
        return round(self.lanes * self.lane_mbps * 1e6)


@dataclass(frozen=True, kw_only=True)
class Optics(_Checked):
    """Lens focal length, the sensor's active-area size (the filmback) and its pixel pitch."""

    focal_mm: float = _f(float, "a positive number (mm)", _pos)
    sensor_width_mm: float = _f(float, "a positive number (mm, active area)", _pos)
    sensor_height_mm: float = _f(float, "a positive number (mm, active area)", _pos)
    pixel_size_um: float = _f(float, "a positive number (um, square pixels)", _pos)


@dataclass(frozen=True, kw_only=True)
class NoiseParams(_Checked):
    """EMVA 1288 figures at unity analog gain; ``ideal`` asks the sensor model to add no noise at all."""

    quantum_efficiency: float = _f(float, "a number in (0, 1]", lambda v: 0 < v <= 1)
    full_well_e: float = _f(float, "a positive number (electrons)", _pos)
    dark_noise_e: float = _f(float, "a number >= 0 (electrons rms)", _nonneg)
    dark_current_e_per_s: float = _f(float, "a number >= 0 (electrons per second)", _nonneg)
    system_gain_dn_per_e: float = _f(float, "a positive number (DN per electron)", _pos)
    dsnu_e: float = _f(float, "a number >= 0 (electrons rms)", _nonneg)
    prnu_fraction: float = _f(float, "a number in [0, 1)", lambda v: 0 <= v < 1)
    black_level_dn: float = _f(float, "a number >= 0 (DN)", _nonneg)
    ideal: bool = _f(bool, "true or false", None, False)
    flux_photons_per_s: float | None = _f(float, "a positive number (photons per pixel per second at linear "
                                          "radiance 1.0), or null for full well at 10 ms", _pos, None)


@dataclass(frozen=True, kw_only=True)
class ExposureLimits(_Checked):
    """Exposure range in lines: at least ``min_lines``, at most frame_length_lines - ``max_margin_lines``."""

    min_lines: int = _f(int, "an integer >= 1 (lines)", lambda v: v >= 1)
    max_margin_lines: int = _f(int, "an integer >= 0 (lines)", _nonneg)


_GAIN = "a positive number (linear gain, 1.0 = unity)"


@dataclass(frozen=True, kw_only=True)
class GainLimits(_Checked):
    """Analog and digital gain ranges as linear multipliers (1.0 = unity)."""

    analog_min: float = _f(float, _GAIN, _pos)
    analog_max: float = _f(float, _GAIN, _pos)
    digital_min: float = _f(float, _GAIN, _pos)
    digital_max: float = _f(float, _GAIN, _pos)
    _rules: ClassVar[tuple[_Rule, ...]] = (
        _Rule("analog_min", lambda s, _, i: s.analog_min <= s.analog_max,
              lambda s, _, i: f"<= analog_max ({s.analog_max!r})"),
        _Rule("digital_min", lambda s, _, i: s.digital_min <= s.digital_max,
              lambda s, _, i: f"<= digital_max ({s.digital_max!r})"),
    )


@dataclass(frozen=True, kw_only=True)
class Register(_Checked):
    """One sensor register: address, width, name, access, meaning; ``reset`` None = not published.

    ``role`` tags the registers the firmware drives (frame length, exposure, ...) whatever their name.
    """

    address: int = _f(int, "an integer in 0..0xFFFF", lambda v: 0 <= v <= 0xFFFF)
    width_bits: int = _f(int, "one of 8, 16, 24, 32", _one_of(8, 16, 24, 32))
    name: str = _f(str, "an UPPER_CASE identifier", lambda v: re.fullmatch(r"[A-Z][A-Z0-9_]*", v))
    access: str = _f(str, "'ro' or 'rw'", _one_of("ro", "rw"))
    meaning: str = _f(str, "a non-empty string", _nonempty)
    reset: int | None = _f(int, "an integer >= 0, or null when not published", _nonneg, None)
    role: str | None = _f(str, f"one of {list(REGISTER_ROLES)}, or null", _one_of(*REGISTER_ROLES), None)
    _rules: ClassVar[tuple[_Rule, ...]] = (
        _Rule("reset", lambda s, _, i: s.reset is None or s.reset < 1 << s.width_bits,
              lambda s, _, i: f"a value that fits {s.width_bits} bits (< {1 << s.width_bits:#x})"),
    )

    @property
    def end(self) -> int:
        """Last byte address the register occupies."""
        return self.address + self.width_bits // 8 - 1


def _size_mm(s: SensorConfig, axis: str) -> float:
    return getattr(s, f"active_{axis}") * s.optics.pixel_size_um / 1000


def _fits(s: SensorConfig, m: SensorMode) -> bool:
    c = m.crop or Crop(0, 0, *m.read_size)
    return c.left + c.width <= s.active_width and c.top + c.height <= s.active_height


def _clash(s: SensorConfig, i: int) -> str | None:
    """The first register before ``registers[i]`` whose address range overlaps it, described."""
    r = s.registers[i]
    for j, o in enumerate(s.registers[:i]):
        if r.address <= o.end and o.address <= r.end:
            return f"registers[{j}] {o.name} ({o.address:#06x}..{o.end:#06x})"
    return None


ModeKey = str | SensorMode | None
_READOUTS = [r.value for r in Readout]


@dataclass(frozen=True, kw_only=True, repr=False)
class SensorConfig(_Checked):
    """Everything rollcam knows about one sensor: geometry, timing, formats, noise, limits, registers."""

    name: str = _f(str, "a lower-case identifier", lambda v: re.fullmatch(r"[a-z0-9_\-]+", v))
    description: str = _f(str, "a non-empty string", _nonempty)
    shutter: str = _f(str, "'rolling' or 'global'", _one_of("rolling", "global"))
    active_width: int = _f(int, "a positive integer (pixels)", _pos)
    active_height: int = _f(int, "a positive integer (pixels)", _pos)
    pixel_rate_hz: int = _f(int, "a positive integer (Hz, e.g. 182_400_000)", _pos)
    readout: Readout = _f(str, f"one of {_READOUTS}", _one_of(*_READOUTS))  # noqa: RUF009
    optics: Optics = _f(Optics, "a mapping {focal_mm, sensor_width_mm, ...}")  # noqa: RUF009
    modes: tuple[SensorMode, ...] = _f(_ListOf(SensorMode), "a non-empty list of modes", _nonempty)
    default_mode: str = _f(str, "the name of one of the modes", _nonempty)
    formats: tuple[str, ...] = _f(_ListOf(str), "a non-empty list of V4L2 fourccs", _nonempty)
    bit_depth: int = _f(int, "an integer in 8..16 (ADC bits)", lambda v: 8 <= v <= 16)
    bayer_order: str = _f(str, f"one of {list(BAYER_ORDERS)}", _one_of(*BAYER_ORDERS))
    noise: NoiseParams = _f(NoiseParams, "a mapping of EMVA 1288 figures")  # noqa: RUF009
    exposure: ExposureLimits = _f(ExposureLimits, "a mapping {min_lines, max_margin_lines}")  # noqa: RUF009
    gain: GainLimits = _f(GainLimits, "a mapping {analog_min, analog_max, ...}")  # noqa: RUF009
    registers: tuple[Register, ...] = _f(_ListOf(Register), "a list of registers (may be empty)")
    sources: tuple[str, ...] = _f(_ListOf(str), "a list of strings", None, ())
    imu: ImuParams | None = _f(ImuParams, "a mapping of IMU figures (Kalibr terms), or absent", None, None)  # noqa: RUF009
    link: Link | None = _f(Link, "a mapping {bus, lanes, lane_mbps}, or absent", None, None)  # noqa: RUF009
    _rules: ClassVar[tuple[_Rule, ...]] = (
        *(_Rule(f"optics.sensor_{ax}_mm",
                lambda s, _, i, ax=ax: math.isclose(_dotted(s, f"optics.sensor_{ax}_mm"), _size_mm(s, ax),
                                                    rel_tol=0.02),
                lambda s, _, i, ax=ax: f"active_{ax} x pixel_size_um = {_size_mm(s, ax):.4g} mm (within 2%)")
          for ax in ("width", "height")),
        _Rule("noise.black_level_dn", lambda s, _, i: s.noise.black_level_dn < (1 << s.bit_depth) - 1,
              lambda s, _, i: f"< {(1 << s.bit_depth) - 1}, the {s.bit_depth}-bit maximum"),
        _Rule("modes[].name", lambda s, m, i: m.name not in [x.name for x in s.modes[:i]],
              lambda s, m, i: "a name no earlier mode has"),
        _Rule("modes[].crop", lambda s, m, i: _fits(s, m),
              lambda s, m, i: f"an area inside the {s.active_width}x{s.active_height} active array "
                              "(without crop: width x height times binning, centred)",
              lambda s, m, i: m.crop or m.read_size),
        _Rule("modes[].frame_length_lines",
              lambda s, m, i: m.frame_length_lines >= s.exposure.min_lines + s.exposure.max_margin_lines,
              lambda s, m, i: f">= exposure.min_lines + max_margin_lines "
                              f"({s.exposure.min_lines} + {s.exposure.max_margin_lines}): room to expose"),
        *(_Rule(f"modes[].{key}", lambda s, m, i, key=key, role=role: getattr(m, key) <= _reg_max(s, role),
                lambda s, m, i, role=role: f"<= {_reg_max(s, role)}, the most its "
                                           f"{_reg_bits(s, role)}-bit {role} register holds")
          for key, role in (("frame_length_lines", "frame_length"), ("line_length_pck", "line_length"))),
        _Rule("default_mode", lambda s, _, i: s.default_mode in [m.name for m in s.modes],
              lambda s, _, i: f"one of {[m.name for m in s.modes]}"),
        _Rule("formats[]", lambda s, f, i: f in FOURCCS,
              lambda s, f, i: f"a known V4L2 fourcc {sorted(FOURCCS)}"),
        _Rule("formats[]", lambda s, f, i: f not in s.formats[:i], lambda s, f, i: "each format listed once"),
        _Rule("formats[]", lambda s, f, i: FOURCCS[f][0] in (None, s.bayer_order),
              lambda s, f, i: f"a processed format or one of bayer_order {s.bayer_order!r}, not "
                              f"{FOURCCS[f][0]}"),
        _Rule("formats[]", lambda s, f, i: FOURCCS[f][1] <= s.bit_depth,
              lambda s, f, i: f"at most bit_depth ({s.bit_depth}) bits, not {FOURCCS[f][1]}"),
        _Rule("registers[].name", lambda s, r, i: r.name not in [x.name for x in s.registers[:i]],
              lambda s, r, i: "a name no earlier register has"),
        _Rule("registers[].address", lambda s, r, i: _clash(s, i) is None,
              lambda s, r, i: f"an address range clear of {_clash(s, i)}",
              lambda s, r, i: f"{r.address:#06x}..{r.end:#06x}"),
        _Rule("registers[].role",
              lambda s, r, i: r.role is None or r.role not in [x.role for x in s.registers[:i]],
              lambda s, r, i: "a role no earlier register has"),
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "readout", Readout(self.readout))

    def __repr__(self) -> str:
        t, m = self.timing(), self.mode()
        return (f"SensorConfig({self.name!r}, {self.shutter}, {self.active_width}x{self.active_height}, mode "
                f"{m.name!r} {t.fps:.2f} fps, line {t.line_time_ns} ns, {len(self.modes)} modes, "
                f"{len(self.registers)} registers)")

    @property
    def rolling(self) -> bool:
        """True for a rolling shutter (rows exposed one line time apart), False for a global shutter."""
        return self.shutter == "rolling"

    def mode(self, name: ModeKey = None) -> SensorMode:
        """The mode called ``name`` (or, failing that, the first of size ``'WxH'``); the default if None."""
        if isinstance(name, SensorMode):
            return name
        name = self.default_mode if name is None else name
        by_size = [m for m in self.modes if f"{m.width}x{m.height}" == name]
        found = [m for m in self.modes if m.name == name] or by_size
        if not found:
            names = [m.name for m in self.modes]
            raise ConfigError(f"sensor {self.name!r} has no mode {name!r}; modes: {names}")
        return found[0]

    def with_mode(self, name: str | SensorMode) -> SensorConfig:
        """A copy whose default mode is ``name`` (a mode name or ``'WxH'``)."""
        return dataclasses.replace(self, default_mode=self.mode(name).name)

    def timing(self, mode: ModeKey = None) -> LineTiming:
        """Integer-ns line timing of a mode (pixel rate, line length, frame length)."""
        m = self.mode(mode)
        return LineTiming(m.pixel_rate_hz or self.pixel_rate_hz, m.line_length_pck, m.frame_length_lines)

    def crop(self, mode: ModeKey = None) -> Crop:
        """The area a mode reads; a mode without ``crop`` reads its ``read_size``, centred on the array."""
        m = self.mode(mode)
        if m.crop is not None:
            return m.crop
        w, h = m.read_size
        # Even offsets keep a centred crop on the same Bayer phase as the full array.
        return Crop((self.active_width - w) // 4 * 2, (self.active_height - h) // 4 * 2, w, h)

    def focal_px(self, mode: ModeKey = None) -> float:
        """Horizontal focal length in output pixels: focal_mm / sensor_width_mm * active_width / binning.

        Cropping keeps the pixel pitch and binning multiplies it, so a full-FOV mode gets
        focal_mm / sensor_width_mm * width and a cropped mode keeps its binning's full-FOV figure.
        """
        m = self.mode(mode)
        return self.optics.focal_mm / self.optics.sensor_width_mm * self.active_width / m.binning[0]

    def intrinsics(self, mode: ModeKey = None) -> tuple[float, float, float, float]:
        """Pinhole ``(fx, fy, cx, cy)`` in output pixels; optical axis at the array centre, x=0 an edge."""
        m, c = self.mode(mode), self.crop(mode)
        fy = self.optics.focal_mm / self.optics.sensor_height_mm * self.active_height / m.binning[1]
        cx = (self.active_width / 2 - c.left) / m.binning[0]
        return self.focal_px(m), fy, cx, (self.active_height / 2 - c.top) / m.binning[1]

    def register(self, key: str | int) -> Register:
        """The register with this name, role or address."""
        for r in self.registers:
            if key in (r.name, r.role) or (isinstance(key, int) and key == r.address):
                return r
        raise ConfigError(f"sensor {self.name!r} has no register {key!r}")


def _reg_bits(sensor: Any, role: str) -> int:
    """Width of the sensor's register with ``role`` (16 bits, the usual, where the map has none)."""
    return next((r.width_bits for r in sensor.registers if r.role == role), 16)


def _reg_max(sensor: Any, role: str) -> int:
    return (1 << _reg_bits(sensor, role)) - 1


def _parse_text(text: str, label: str) -> SensorConfig:
    raw = read_yaml(text, label)
    try:
        return _parse_section(SensorConfig, raw, "")
    except _Invalid as e:
        raise ConfigError(f"{label}: {e}") from None


@functools.cache
def _load_packaged(name: str) -> SensorConfig:
    res = resources.files(_PACKAGE) / f"{name}.yaml"
    if not res.is_file():
        raise ConfigError(f"no sensor named {name!r}; known sensors: {list_sensors()}")
    return _parse_text(res.read_text(encoding="utf-8"), str(res))


def load_sensor(name_or_path: str | os.PathLike[str]) -> SensorConfig:
    """Load and validate a sensor description: a bare name from rollcam.hw_configs, or a YAML file path."""
    text = os.fspath(name_or_path)
    is_path = "/" in text or os.sep in text or text.endswith((".yaml", ".yml"))
    if isinstance(name_or_path, os.PathLike) or is_path:
        try:
            body = Path(text).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as e:
            raise ConfigError(f"{text}: cannot read sensor description: {e}") from None
        return _parse_text(body, text)
    if not re.fullmatch(r"[A-Za-z0-9_\-]+", text):
        raise ConfigError(f"sensor name {text!r} is neither a name (letters, digits, _ -) nor a .yaml path")
    return _load_packaged(text.lower())


def list_sensors() -> list[str]:
    """Names of the sensor descriptions shipped in rollcam.hw_configs."""
    return sorted(f.name[:-5] for f in resources.files(_PACKAGE).iterdir() if f.name.endswith(".yaml"))
