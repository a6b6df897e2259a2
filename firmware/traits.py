"""Per-sensor facts the firmware needs beyond hw_configs: gain codes, register bit fields, test patterns.

Each entry is data read off the sensor's Linux driver (the same sources its hw_config cites); ``DEFAULT``
covers sensors without an entry. ``traits_for(name)`` is the only lookup.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class GainCodec:
    """Register code <-> linear gain: ``smia`` is base / (base - code), ``linear`` is code / base."""

    kind: str
    base: int

    def to_gain(self, code: int) -> float:
        """Linear gain of a register code."""
        if self.kind == "smia":
            return self.base / max(self.base - int(code), 1)
        return int(code) / self.base

    def to_code(self, gain: float) -> int:
        """Nearest register code of a linear gain."""
        if self.kind == "smia":
            return round(self.base - self.base / gain)
        return round(gain * self.base)


TEST_PATTERNS = ("none", "solid", "bars", "fade_bars", "pn9", "walking_ones")
"""Test patterns the firmware can draw (``firmware.patterns``) in place of the scene."""


@dataclass(frozen=True)
class SensorTraits:
    """Register encodings of one sensor family.

    ``test_pattern_codes`` maps a pattern to its TEST_PATTERN register value; its order is the V4L2 menu order
    (the imx219 driver's: disabled, colour bars, solid, grey bars, PN9). ``stream_bits`` is the MODE_SELECT
    mask that means streaming. ``exposure_shift`` is the fractional-line bits of the exposure register.
    """

    maker: str = "rollcam"
    analog: GainCodec = GainCodec("linear", 256)
    digital: GainCodec = GainCodec("linear", 256)
    exposure_shift: int = 0
    hflip_bit: int | None = 0
    vflip_bit: int | None = 1
    stream_bits: int = 0x01
    test_pattern_codes: dict[str, int] = field(default_factory=lambda: {
        "none": 0, "bars": 2, "solid": 1, "fade_bars": 3, "pn9": 4})
    dual_shutter: bool = False


_SMIA_TP = {"none": 0, "bars": 2, "solid": 1, "fade_bars": 3, "pn9": 4}
TRAITS: dict[str, SensorTraits] = {
    "imx219": SensorTraits("Sony", analog=GainCodec("smia", 256), test_pattern_codes=_SMIA_TP),
    "imx477": SensorTraits("Sony", analog=GainCodec("smia", 1024), test_pattern_codes=_SMIA_TP),
    "imx378": SensorTraits("Sony", analog=GainCodec("smia", 1024), test_pattern_codes=_SMIA_TP),
    "imx708": SensorTraits("Sony", analog=GainCodec("smia", 1024), test_pattern_codes=_SMIA_TP),
    "imx500": SensorTraits("Sony", analog=GainCodec("smia", 1024), test_pattern_codes=_SMIA_TP),
    # AR0234: the coarse/fine analog gain field is approximated as a linear code / 16.
    "ar0234": SensorTraits("onsemi", analog=GainCodec("linear", 16), digital=GainCodec("linear", 128),
                           hflip_bit=14, vflip_bit=15, stream_bits=0x04,
                           test_pattern_codes={"none": 0, "bars": 2, "solid": 1, "fade_bars": 3,
                                               "walking_ones": 256}),
    "ov9281": SensorTraits("OmniVision", analog=GainCodec("linear", 16), exposure_shift=4,
                           hflip_bit=None, vflip_bit=None, test_pattern_codes={"none": 0x00, "bars": 0x80}),
    # The study's virtual camera has no chip: it renders either shutter on request.
    "letsroll": SensorTraits("rollcam", hflip_bit=None, vflip_bit=None,
                             test_pattern_codes={"none": 0, "bars": 2, "solid": 1, "fade_bars": 3, "pn9": 4},
                             dual_shutter=True),
}
DEFAULT = SensorTraits()


def traits_for(sensor_name: str) -> SensorTraits:
    """The traits of a sensor by name (``DEFAULT`` when it has no entry)."""
    return TRAITS.get(sensor_name, DEFAULT)
