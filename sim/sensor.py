"""The emulated sensor's output path: exposed radiance -> ADC samples -> the requested V4L2 format.

``SensorPipeline`` joins the EMVA model (``rollcam.sim.noise``), the raw layouts (``rollcam.sim.formats``)
and the preview ISP (``rollcam.sim.isp``). A raw fourcc (Bayer or mono, unpacked or CSI-2 packed) is the ADC
output itself, straight to the consumer (no ISP); a processed one (BGR3, RGB3, YUYV, NV12, YU12, and GREY on
a colour sensor) goes through the preview ISP, whose white level is the full well at the frame's gain.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.common.values import SERIAL

from .codecs import codec
from .formats import FORMATS, PixelFormat, pixel_format
from .hwconfig import SensorConfig
from .isp import IspParams, preview
from .noise import STAGES, SensorModel, split_gain
from .render.result import LinearFrame


@dataclass(frozen=True)
class SensorPipeline:
    """Radiance to delivered pixels for one stream: model, output fourcc, total gain and ISP settings."""

    model: SensorModel
    fourcc: str
    analog_gain: float = 1.0
    digital_gain: float = 1.0
    gain_clamped: bool = False
    origin: tuple[int, int] = (0, 0)
    array_width: int | None = None
    isp: IspParams = field(default_factory=IspParams)
    hflip: bool = False
    vflip: bool = False

    @classmethod
    def for_sensor(cls, sensor: SensorConfig, fourcc: str = "BGR3", *, gain: float = 1.0, serial: str = SERIAL,
                   seed: int = 0, stages: frozenset[str] | None = None, origin: tuple[int, int] = (0, 0),
                   wb_gains: tuple[float, float, float] | None = (1.0, 1.0, 1.0), hflip: bool = False,
                   vflip: bool = False, size: tuple[int, int] = (2, 2)) -> SensorPipeline:
        """The pipeline of ``sensor`` delivering ``fourcc``; ``gain`` is split into analog then digital.

        With flips, the array is read mirrored: the delivered raw fourcc is the one of the order the output
        starts on (``size`` decides the parity), whichever of the two orders' fourccs was asked for.
        """
        f = pixel_format(fourcc)
        cfa = sensor.bayer_order
        out_cfa = flipped_cfa(cfa, size, hflip, vflip)
        if _samples(f, cfa):
            if f.cfa == out_cfa != cfa:
                f = pixel_format(_same_layout(f, cfa))
            if f.cfa != cfa:
                want = "a mono format (GREY, Y10 , ...)" if cfa == "mono" else f"one of Bayer order {cfa!r}"
                raise ConfigError(f"format {fourcc!r} samples CFA {f.cfa!r}; sensor {sensor.name!r} delivers {want}")
            if f.bits > sensor.bit_depth:
                raise ConfigError(f"format {fourcc!r} holds {f.bits} bits, more than sensor {sensor.name!r}'s "
                                  f"{sensor.bit_depth}-bit ADC")
        g = sensor.gain
        a, d, clamped = split_gain(gain, (g.analog_min, g.analog_max), (g.digital_min, g.digital_max))
        model = SensorModel(sensor.noise, sensor.bit_depth, cfa, serial=serial, seed=seed,
                            stages=frozenset(STAGES) if stages is None else stages)
        k = model.system_gain(a, d)
        white = min(sensor.noise.black_level_dn + k * sensor.noise.full_well_e, float(model.max_dn))
        isp = IspParams(black_level_dn=sensor.noise.black_level_dn, white_level_dn=white, wb_gains=wb_gains)
        out = _same_layout(f, out_cfa) if _samples(f, cfa) else f.fourcc
        return cls(model, out, a, d, clamped, origin, sensor.active_width, isp, hflip, vflip)

    @property
    def raw(self) -> bool:
        """True when frames are the ADC output (no ISP)."""
        return _samples(pixel_format(self.fourcc), self.model.cfa)

    def samples(self, radiance: np.ndarray | LinearFrame, exposure_ns: int, frame_index: int) -> np.ndarray:
        """ADC samples ``uint16 (H, W)`` of one exposed frame, in output orientation (flips applied).

        ``radiance`` is in scene orientation; the array (its CFA and fixed patterns) is exposed as it sits and
        read out mirrored, as a sensor's flip bits do.
        """
        dn = self.model.expose(radiance, exposure_ns, frame_index, analog_gain=self.analog_gain,
                               digital_gain=self.digital_gain, origin=self.origin, array_width=self.array_width)
        return np.ascontiguousarray(flip(dn, self.hflip, self.vflip))

    def deliver(self, radiance: np.ndarray | LinearFrame, exposure_ns: int, frame_index: int) -> np.ndarray:
        """Frame data in ``fourcc``'s layout (encoded by ``rollcam.sim.codecs``)."""
        return self.encode(self.samples(radiance, exposure_ns, frame_index))

    def encode(self, dn: np.ndarray) -> np.ndarray:
        """ADC samples (``samples``) in ``fourcc``'s layout: the raw layout, or the preview ISP's picture."""
        if self.raw:
            return codec(self.fourcc).encode(dn, sample_bits=self.model.bit_depth)
        h, w = dn.shape
        order = flipped_cfa(self.model.cfa, (w, h), self.hflip, self.vflip)
        return codec(self.fourcc).encode(preview(dn, order, self.isp))

    def info(self) -> dict[str, Any]:
        """What a frame's metadata records about the sensor path."""
        return {"pixel_format": self.fourcc, "analog_gain": round(self.analog_gain, 6),
                "digital_gain": round(self.digital_gain, 6), "gain_clamped": self.gain_clamped,
                "bit_depth": self.model.bit_depth, "cfa": self.model.cfa, "serial": self.model.serial,
                "noise_stages": sorted(self.model.stages),
                "black_level_dn": self.model.noise.black_level_dn, "hflip": self.hflip, "vflip": self.vflip}


def _samples(f: PixelFormat, cfa: str) -> bool:
    """True when ``f`` delivers the sensor's own samples: a raw format, except GREY on a colour sensor (luma)."""
    return f.is_raw and not (f.fourcc == "GREY" and cfa != "mono")


def flip(a: np.ndarray, hflip: bool, vflip: bool) -> np.ndarray:
    """A view of ``a`` mirrored left-right and/or top-bottom."""
    return a[::-1 if vflip else 1, ::-1 if hflip else 1]


def flipped_cfa(order: str, size: tuple[int, int], hflip: bool, vflip: bool) -> str:
    """The Bayer order a mirrored readout of a ``size`` (W, H) array starts on.

    For even sizes this is ``rollcam.sim.formats.flipped_order``; an odd size keeps the parity along that axis.
    """
    if order == "mono":
        return order
    w, h = size
    tile = [order[0:2], order[2:4]]
    return "".join(tile[((h - 1 - dy) if vflip else dy) % 2][((w - 1 - dx) if hflip else dx) % 2]
                   for dy in (0, 1) for dx in (0, 1))


def _same_layout(f: PixelFormat, cfa: str) -> str:
    """The fourcc with ``f``'s bits and packing for CFA ``cfa``."""
    for g in FORMATS.values():
        if g.cfa == cfa and g.bits == f.bits and g.packing == f.packing:
            return g.fourcc
    raise ConfigError(f"no {f.bits}-bit {f.packing} format for CFA {cfa!r}")
