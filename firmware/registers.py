"""The sensor's register map (from its hw_config) over ``SensorState``: reads and writes by address or name.

Registers tagged with a ``role`` in the hw_config are views of the programmed state, encoded with the
sensor's traits (gain codes, flip bits, exposure fraction bits, test-pattern codes); writing one has the
effect it has on the real part. Other registers are plain storage holding their reset value (0 where none
is published). Multi-byte values are big-endian as on CCI (I2C); an access must name a register's first byte.
"""

from __future__ import annotations

from collections.abc import Callable

from rollcam.common.errors import ConfigError, DeviceError
from rollcam.sim.hwconfig import Register, SensorConfig

from .controls import SensorState, set_control


def _orientation_read(s: SensorState, _r: Register) -> int:
    t = s.traits
    return (int(s.hflip) << t.hflip_bit if t.hflip_bit is not None else 0) | \
        (int(s.vflip) << t.vflip_bit if t.vflip_bit is not None else 0)


def _orientation_write(s: SensorState, _r: Register, value: int) -> None:
    for axis in ("hflip", "vflip"):
        bit = getattr(s.traits, f"{axis}_bit")
        if bit is not None:
            s.set_flip(axis, bool(value >> bit & 1))


def _pattern_write(s: SensorState, r: Register, value: int) -> None:
    names = {code: name for name, code in s.traits.test_pattern_codes.items()}
    if value not in names:
        raise ConfigError(f"{r.name} value {value:#x} is not a test pattern code; codes: "
                          f"{ {f'{c:#x}': n for c, n in names.items()} }")
    s.set_test_pattern(names[value])


def _set_line_length(s: SensorState, _r: Register, value: int) -> None:
    s.line_length_pck = max(int(value), s.width)


ROLE_CODECS: dict[str, tuple[Callable[[SensorState, Register], int],
                             Callable[[SensorState, Register, int], object] | None]] = {
    "chip_id": (lambda s, r: r.reset or 0, None),
    "mode_select": (lambda s, r: s.traits.stream_bits if s.streaming else 0, None),  # the camera handles writes
    "frame_length": (lambda s, r: s.frame_length_lines, lambda s, r, v: s.set_frame_length(v)),
    "line_length": (lambda s, r: s.line_length_pck, _set_line_length),
    "exposure": (lambda s, r: s.exposure_lines << s.traits.exposure_shift,
                 lambda s, r, v: s.set_exposure(v >> s.traits.exposure_shift)),
    "analog_gain": (lambda s, r: s.analog_code, lambda s, r, v: set_control(s, "analogue_gain", v)),
    "digital_gain": (lambda s, r: s.digital_code, lambda s, r, v: set_control(s, "digital_gain", v)),
    "orientation": (_orientation_read, _orientation_write),
    "test_pattern": (lambda s, r: s.traits.test_pattern_codes[s.test_pattern], _pattern_write),
}
"""role -> (read, write) of the registers the firmware drives."""


class RegisterFile:
    """Register reads and writes of one sensor over a ``SensorState``; plain registers are kept here.

    ``on_mode_select(streaming)`` starts and stops the stream.
    """

    def __init__(self, sensor: SensorConfig, on_mode_select: Callable[[bool], None]) -> None:
        self.sensor = sensor
        self.on_mode_select = on_mode_select
        self.by_address = {r.address: r for r in sensor.registers}
        self.plain = {r.address: r.reset or 0 for r in sensor.registers if r.role is None}

    def lookup(self, key: str | int) -> Register:
        """The register at address ``key`` (int) or named ``key`` (str, case-insensitive)."""
        regs = self.sensor.registers
        if not regs:
            raise DeviceError(f"sensor {self.sensor.name!r} has no register map")
        if isinstance(key, str):
            found = next((r for r in regs if r.name == key.upper()), None)
            if found is None:
                raise ConfigError(f"no register named {key!r}; names: {[r.name for r in regs]}")
            return found
        if key in self.by_address:
            return self.by_address[key]
        inside = next((r for r in regs if r.address < key <= r.end), None)
        if inside is not None:
            raise ConfigError(f"address {key:#06x} is inside {inside.name} ({inside.address:#06x}, "
                              f"{inside.width_bits} bits); access it at its first byte")
        raise ConfigError(f"no register at address {key:#06x}")

    def read(self, state: SensorState, key: str | int) -> int:
        """Value of a register."""
        r = self.lookup(key)
        if r.role is None:
            return self.plain[r.address]
        return ROLE_CODECS[r.role][0](state, r) & ((1 << r.width_bits) - 1)

    def write(self, state: SensorState, key: str | int, value: int) -> int:
        """Write a register into ``state`` with the part's side effects; returns the value it then reads back
        (a MODE_SELECT write goes to ``on_mode_select`` instead)."""
        r = self.lookup(key)
        if r.access == "ro":
            raise DeviceError(f"register {r.name} ({r.address:#06x}) is read-only")
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 1 << r.width_bits:
            raise ConfigError(f"value {value!r} does not fit register {r.name} ({r.width_bits} bits)")
        if r.role is None:
            self.plain[r.address] = value
        elif r.role == "mode_select":
            self.on_mode_select(bool(value & state.traits.stream_bits))
            state.streaming = bool(value & state.traits.stream_bits)
        else:
            writer = ROLE_CODECS[r.role][1]
            if writer is None:
                raise DeviceError(f"register {r.name} is not writable")
            writer(state, r, value)
        return self.read(state, r.address)
