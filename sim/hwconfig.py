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
    Checked,
    InvalidKey,
    ListOf,
    Rule,
    dotted,
    nonempty,
    nonnegative,
    one_of,
    parse_section,
    positive,
    spec,
)
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
class Crop(Checked):
    """Sensor area a mode reads, in full-resolution active-pixel coordinates."""

    left: int = spec(int, "an integer >= 0 (pixels)", nonnegative)
    top: int = spec(int, "an integer >= 0 (pixels)", nonnegative)
    width: int = spec(int, "a positive integer (pixels)", positive)
    height: int = spec(int, "a positive integer (pixels)", positive)


@dataclass(frozen=True, kw_only=True)
class SensorMode(Checked):
    """One readout mode: output size, line and frame length, optional binning, crop and own pixel rate."""

    name: str = spec(str, "a non-empty string", nonempty)
    width: int = spec(int, "a positive integer (output pixels per line)", positive)
    height: int = spec(int, "a positive integer (output lines)", positive)
    line_length_pck: int = spec(int, "a positive integer (pixel clocks per line)", positive)
    frame_length_lines: int = spec(int, "a positive integer (lines per frame)", positive)
    binning: tuple[int, ...] = spec(ListOf(int), "[horizontal, vertical], factors >= 1",
                                    lambda v: len(v) == 2 and min(v) >= 1, (1, 1))
    crop: Crop | None = spec(Crop, "a mapping {left, top, width, height}", None, None)  # noqa: RUF009
    pixel_rate_hz: int | None = spec(int, "a positive integer (Hz), overriding the sensor's", positive, None)
    _rules: ClassVar[tuple[Rule, ...]] = (
        Rule("line_length_pck", lambda s, _, i: s.line_length_pck >= s.width,
              lambda s, _, i: f">= width ({s.width}): a line cannot be shorter than its active pixels"),
        Rule("frame_length_lines", lambda s, _, i: s.frame_length_lines >= s.height,
              lambda s, _, i: f">= height ({s.height}): a frame cannot hold fewer lines than it outputs"),
        Rule("crop", lambda s, _, i: s.crop is None or (s.crop.width, s.crop.height) == s.read_size,
              lambda s, _, i: "width x height = output size x binning = {}x{}".format(*s.read_size)),
    )

    @property
    def read_size(self) -> tuple[int, int]:
        """Width and height of the sensor area this mode reads (output size times binning)."""
        return self.width * self.binning[0], self.height * self.binning[1]


@dataclass(frozen=True, kw_only=True)
class Link(Checked):
    """The sensor's data link to its host: MIPI CSI-2 (``lanes`` x ``lane_mbps``) or USB (``lane_mbps`` is the
    bus's signalling rate, ``lanes`` 1), for the bandwidth ledger (``rollcam.firmware.ledger``)."""

    bus: str = spec(str, "'csi2' or 'usb'", one_of("csi2", "usb"))
    lanes: int = spec(int, "an integer in 1..8 (data lanes)", lambda v: 1 <= v <= 8)
    lane_mbps: float = spec(float, "a positive number (Mbit/s per lane)", positive)

    @property
    def capacity_bps(self) -> int:
        """Raw bits per second the link carries, all lanes together."""
        return round(self.lanes * self.lane_mbps * 1e6)


@dataclass(frozen=True, kw_only=True)
class Optics(Checked):
    """Lens focal length, the sensor's active-area size (the filmback) and its pixel pitch."""

    focal_mm: float = spec(float, "a positive number (mm)", positive)
    sensor_width_mm: float = spec(float, "a positive number (mm, active area)", positive)
    sensor_height_mm: float = spec(float, "a positive number (mm, active area)", positive)
    pixel_size_um: float = spec(float, "a positive number (um, square pixels)", positive)


@dataclass(frozen=True, kw_only=True)
class NoiseParams(Checked):
    """EMVA 1288 figures at unity analog gain; ``ideal`` asks the sensor model to add no noise at all."""

    quantum_efficiency: float = spec(float, "a number in (0, 1]", lambda v: 0 < v <= 1)
    full_well_e: float = spec(float, "a positive number (electrons)", positive)
    dark_noise_e: float = spec(float, "a number >= 0 (electrons rms)", nonnegative)
    dark_current_e_per_s: float = spec(float, "a number >= 0 (electrons per second)", nonnegative)
    system_gain_dn_per_e: float = spec(float, "a positive number (DN per electron)", positive)
    dsnu_e: float = spec(float, "a number >= 0 (electrons rms)", nonnegative)
    prnu_fraction: float = spec(float, "a number in [0, 1)", lambda v: 0 <= v < 1)
    black_level_dn: float = spec(float, "a number >= 0 (DN)", nonnegative)
    ideal: bool = spec(bool, "true or false", None, False)
    flux_photons_per_s: float | None = spec(float, "a positive number (photons per pixel per second at linear "
                                            "radiance 1.0), or null for full well at 10 ms", positive, None)


@dataclass(frozen=True, kw_only=True)
class ExposureLimits(Checked):
    """Exposure range in lines: at least ``min_lines``, at most frame_length_lines - ``max_margin_lines``."""

    min_lines: int = spec(int, "an integer >= 1 (lines)", lambda v: v >= 1)
    max_margin_lines: int = spec(int, "an integer >= 0 (lines)", nonnegative)


_GAIN = "a positive number (linear gain, 1.0 = unity)"


@dataclass(frozen=True, kw_only=True)
class GainLimits(Checked):
    """Analog and digital gain ranges as linear multipliers (1.0 = unity)."""

    analog_min: float = spec(float, _GAIN, positive)
    analog_max: float = spec(float, _GAIN, positive)
    digital_min: float = spec(float, _GAIN, positive)
    digital_max: float = spec(float, _GAIN, positive)
    _rules: ClassVar[tuple[Rule, ...]] = (
        Rule("analog_min", lambda s, _, i: s.analog_min <= s.analog_max,
              lambda s, _, i: f"<= analog_max ({s.analog_max!r})"),
        Rule("digital_min", lambda s, _, i: s.digital_min <= s.digital_max,
              lambda s, _, i: f"<= digital_max ({s.digital_max!r})"),
    )


@dataclass(frozen=True, kw_only=True)
class Register(Checked):
    """One sensor register: address, width, name, access, meaning; ``reset`` None = not published.

    ``role`` tags the registers the firmware drives (frame length, exposure, ...) whatever their name.
    """

    address: int = spec(int, "an integer in 0..0xFFFF", lambda v: 0 <= v <= 0xFFFF)
    width_bits: int = spec(int, "one of 8, 16, 24, 32", one_of(8, 16, 24, 32))
    name: str = spec(str, "an UPPER_CASE identifier", lambda v: re.fullmatch(r"[A-Z][A-Z0-9_]*", v))
    access: str = spec(str, "'ro' or 'rw'", one_of("ro", "rw"))
    meaning: str = spec(str, "a non-empty string", nonempty)
    reset: int | None = spec(int, "an integer >= 0, or null when not published", nonnegative, None)
    role: str | None = spec(str, f"one of {list(REGISTER_ROLES)}, or null", one_of(*REGISTER_ROLES), None)
    _rules: ClassVar[tuple[Rule, ...]] = (
        Rule("reset", lambda s, _, i: s.reset is None or s.reset < 1 << s.width_bits,
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
class SensorConfig(Checked):
    """Everything rollcam knows about one sensor: geometry, timing, formats, noise, limits, registers."""

    name: str = spec(str, "a lower-case identifier", lambda v: re.fullmatch(r"[a-z0-9_\-]+", v))
    description: str = spec(str, "a non-empty string", nonempty)
    shutter: str = spec(str, "'rolling' or 'global'", one_of("rolling", "global"))
    active_width: int = spec(int, "a positive integer (pixels)", positive)
    active_height: int = spec(int, "a positive integer (pixels)", positive)
    pixel_rate_hz: int = spec(int, "a positive integer (Hz, e.g. 182_400_000)", positive)
    readout: Readout = spec(str, f"one of {_READOUTS}", one_of(*_READOUTS))  # noqa: RUF009
    optics: Optics = spec(Optics, "a mapping {focal_mm, sensor_width_mm, ...}")  # noqa: RUF009
    modes: tuple[SensorMode, ...] = spec(ListOf(SensorMode), "a non-empty list of modes", nonempty)
    default_mode: str = spec(str, "the name of one of the modes", nonempty)
    formats: tuple[str, ...] = spec(ListOf(str), "a non-empty list of V4L2 fourccs", nonempty)
    bit_depth: int = spec(int, "an integer in 8..16 (ADC bits)", lambda v: 8 <= v <= 16)
    bayer_order: str = spec(str, f"one of {list(BAYER_ORDERS)}", one_of(*BAYER_ORDERS))
    noise: NoiseParams = spec(NoiseParams, "a mapping of EMVA 1288 figures")  # noqa: RUF009
    exposure: ExposureLimits = spec(ExposureLimits, "a mapping {min_lines, max_margin_lines}")  # noqa: RUF009
    gain: GainLimits = spec(GainLimits, "a mapping {analog_min, analog_max, ...}")  # noqa: RUF009
    registers: tuple[Register, ...] = spec(ListOf(Register), "a list of registers (may be empty)")
    sources: tuple[str, ...] = spec(ListOf(str), "a list of strings", None, ())
    imu: ImuParams | None = spec(ImuParams, "a mapping of IMU figures (Kalibr terms), or absent", None, None)  # noqa: RUF009
    link: Link | None = spec(Link, "a mapping {bus, lanes, lane_mbps}, or absent", None, None)  # noqa: RUF009
    _rules: ClassVar[tuple[Rule, ...]] = (
        *(Rule(f"optics.sensor_{ax}_mm",
                lambda s, _, i, ax=ax: math.isclose(dotted(s, f"optics.sensor_{ax}_mm"), _size_mm(s, ax),
                                                    rel_tol=0.02),
                lambda s, _, i, ax=ax: f"active_{ax} x pixel_size_um = {_size_mm(s, ax):.4g} mm (within 2%)")
          for ax in ("width", "height")),
        Rule("noise.black_level_dn", lambda s, _, i: s.noise.black_level_dn < (1 << s.bit_depth) - 1,
              lambda s, _, i: f"< {(1 << s.bit_depth) - 1}, the {s.bit_depth}-bit maximum"),
        Rule("modes[].name", lambda s, m, i: m.name not in [x.name for x in s.modes[:i]],
              lambda s, m, i: "a name no earlier mode has"),
        Rule("modes[].crop", lambda s, m, i: _fits(s, m),
              lambda s, m, i: f"an area inside the {s.active_width}x{s.active_height} active array "
                              "(without crop: width x height times binning, centred)",
              lambda s, m, i: m.crop or m.read_size),
        Rule("modes[].frame_length_lines",
              lambda s, m, i: m.frame_length_lines >= s.exposure.min_lines + s.exposure.max_margin_lines,
              lambda s, m, i: f">= exposure.min_lines + max_margin_lines "
                              f"({s.exposure.min_lines} + {s.exposure.max_margin_lines}): room to expose"),
        *(Rule(f"modes[].{key}", lambda s, m, i, key=key, role=role: getattr(m, key) <= _reg_max(s, role),
                lambda s, m, i, role=role: f"<= {_reg_max(s, role)}, the most its "
                                           f"{_reg_bits(s, role)}-bit {role} register holds")
          for key, role in (("frame_length_lines", "frame_length"), ("line_length_pck", "line_length"))),
        Rule("default_mode", lambda s, _, i: s.default_mode in [m.name for m in s.modes],
              lambda s, _, i: f"one of {[m.name for m in s.modes]}"),
        Rule("formats[]", lambda s, f, i: f in FOURCCS,
              lambda s, f, i: f"a known V4L2 fourcc {sorted(FOURCCS)}"),
        Rule("formats[]", lambda s, f, i: f not in s.formats[:i], lambda s, f, i: "each format listed once"),
        Rule("formats[]", lambda s, f, i: FOURCCS[f][0] in (None, s.bayer_order),
              lambda s, f, i: f"a processed format or one of bayer_order {s.bayer_order!r}, not "
                              f"{FOURCCS[f][0]}"),
        Rule("formats[]", lambda s, f, i: FOURCCS[f][1] <= s.bit_depth,
              lambda s, f, i: f"at most bit_depth ({s.bit_depth}) bits, not {FOURCCS[f][1]}"),
        Rule("registers[].name", lambda s, r, i: r.name not in [x.name for x in s.registers[:i]],
              lambda s, r, i: "a name no earlier register has"),
        Rule("registers[].address", lambda s, r, i: _clash(s, i) is None,
              lambda s, r, i: f"an address range clear of {_clash(s, i)}",
              lambda s, r, i: f"{r.address:#06x}..{r.end:#06x}"),
        Rule("registers[].role",
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
        return parse_section(SensorConfig, raw, "")
    except InvalidKey as e:
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
