"""The emulated Pi camera behind ``Picamera2``: one ``FirmwareCamera`` described as libcamera describes a camera.

Which cameras exist comes from the environment variable ``ROLLCAM_PICAMERA2``: sources separated by ``;``,
each a sensor name or an ``emu:`` URI (``emu:imx477?scene=flat&level=0.4``); camera ``N`` is the N-th
(default: one ``imx219``). ``rollcam run`` and the ``rollcam_picamera2`` pytest fixture set it.

``PiCamera`` lists the sensor's raw modes (one per raw bit depth and sensor mode, named as libcamera names them:
``SRGGB10_CSI2P``), its properties and controls with their (min, max, default), programs a mode, and applies
libcamera controls at a frame boundary through the firmware's one control path
(``rollcam.firmware.controls``), so a value set here is what every other door of the device reads.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from typing import Any

from rollcam.common.errors import SourceError
from rollcam.firmware import controls as ctl
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.pixfmt import raw_formats
from rollcam.firmware.spec import CameraSpec
from rollcam.host.servers.standins import PICAMERA2_ENV
from rollcam.host.sources.emu import device_spec
from rollcam.sim import formats as sf
from rollcam.sim.frame import Frame
from rollcam.sim.hwconfig import SensorMode

from . import _cnn

CFA_CODES = {"RGGB": 0, "GRBG": 1, "GBRG": 2, "BGGR": 3, "mono": 5}
"""libcamera's ColorFilterArrangement values."""

AUTO_CONTROLS: dict[str, tuple[Any, Any, Any]] = {
    "AeEnable": (False, True, True), "AwbEnable": (False, True, True), "AeMeteringMode": (0, 3, 0),
    "AeConstraintMode": (0, 3, 0), "AeExposureMode": (0, 3, 0), "ExposureValue": (-8.0, 8.0, 0.0),
    "AwbMode": (0, 7, 0), "Brightness": (-1.0, 1.0, 0.0), "Contrast": (0.0, 32.0, 1.0),
    "Saturation": (0.0, 32.0, 1.0), "Sharpness": (0.0, 16.0, 1.0), "ColourGains": (0.0, 32.0, None),
    "NoiseReductionMode": (0, 4, 0), "StatsOutputEnable": (False, True, False), "HdrMode": (0, 4, 0),
}
"""Controls accepted and echoed in the metadata but without effect (no AE/AWB algorithms run), except
``ColourGains``, which sets the ISP's red and blue gains."""

FOCUS_CONTROLS: dict[str, tuple[Any, Any, Any]] = {
    "AfMode": (0, 2, 0), "AfTrigger": (0, 1, 0), "AfRange": (0, 2, 0), "AfSpeed": (0, 1, 0),
    "LensPosition": (0.0, 15.0, 1.0), "AfWindows": ((0, 0, 0, 0), (65535, 65535, 65535, 65535), (0, 0, 0, 0)),
    "AfMetering": (0, 1, 0), "AfPause": (0, 2, 0),
}
"""The autofocus controls of a camera with a lens driver (the IMX708's Camera Module 3): accepted, no effect."""

FOCUS_SENSORS = {"imx708"}


def sources() -> list[str]:
    """The emulated cameras' sources, from ``ROLLCAM_PICAMERA2`` (default: one imx219)."""
    text = os.environ.get(PICAMERA2_ENV, "").strip()
    return [s.strip() for s in text.split(";") if s.strip()] if text else ["imx219"]


def spec_of(source: str) -> CameraSpec:
    """The camera spec of a sensor name or ``emu:`` URI; SourceError naming the source when it is bad. A
    ``faults=`` plan there is the V4L2 device's (``rollcam run``); the stand-in injects only the AI Camera's faults
    of it (``loaderfail``, ``fetimeout``, ``dnn_us``: ``PiCamera``)."""
    return device_spec(source, SourceError)[0]


@dataclass(frozen=True)
class RawMode:
    """One sensor mode as libcamera lists it: raw format name, size, and the fourccs that stream it."""

    format: str
    bit_depth: int
    size: tuple[int, int]
    mode: SensorMode
    fourccs: dict[bool, str] = field(compare=False)  # packed? -> fourcc in the sensor's own Bayer order


def _name(f: sf.PixelFormat, cfa: str | None = None) -> str:
    """libcamera's name of a raw fourcc (SRGGB10_CSI2P, SRGGB10, R8), optionally in another Bayer order."""
    cfa = cfa or f.cfa
    base = f"R{f.bits}" if cfa == "mono" else f"S{cfa}{f.bits}"
    return base + ("_CSI2P" if f.packing == "csi2" else "")


def raw_modes(spec: CameraSpec) -> list[RawMode]:
    """Every raw mode: per raw bit depth (deepest first), per sensor mode (smallest first); the packed
    fourcc names the mode when the sensor has one, as on a Pi."""
    sensor = spec.sensor
    depths: dict[int, dict[bool, str]] = {}
    for fourcc in raw_formats(sensor):
        f = sf.pixel_format(fourcc)
        depths.setdefault(f.bits, {})[f.packing == "csi2"] = f.fourcc
    out = []
    for bits in sorted(depths, reverse=True):
        fourccs = depths[bits]
        name = _name(sf.pixel_format(fourccs.get(True) or fourccs[False]))
        out.extend(RawMode(name, bits, (m.width, m.height), m, fourccs)
                   for m in sorted(sensor.modes, key=lambda m: m.width * m.height))
    return out


class PiCamera:
    """The firmware camera of one source, with libcamera's view of its modes, properties and controls."""

    def __init__(self, source: str, num: int) -> None:
        self.source, self.num = source, num
        self.base = spec_of(source)
        # A network named in the source (insensor=...) runs whatever IMX500() is given; else IMX500's does.
        self._own_network = self.base.insensor is None
        self.cnn = _cnn.program_of(num)
        if self.cnn is not None and self._own_network:
            self.base = self.base.with_options(self.cnn.options())
        self.device = FirmwareCamera(self.base)
        self.device.insensor.set_faults(device_spec(source, SourceError)[1])  # the AI Camera's failures
        self.sensor = self.base.sensor
        self.modes = raw_modes(self.base)
        if not self.modes:
            raise SourceError(f"sensor {self.sensor.name!r} has no raw formats; picamera2 needs a raw sensor")
        self.frame_limits_us: tuple[int, int] = (0, 1 << 62)
        self.exposure_us = 0  # 0: not set (the source's exposure), as libcamera's 0 means automatic
        self.analogue_gain = 0.0
        self.extra: dict[str, Any] = {}  # accepted controls without effect on the sensor (AeEnable, ...)
        self.af_state = 0  # libcamera's AfState: Idle, Scanning, Focused, Failed
        self.scaler_crop: tuple[int, int, int, int] | None = None

    @property
    def camera_id(self) -> str:
        """libcamera's id of the camera (as a Pi names a CSI camera)."""
        return f"/base/soc/i2c0mux/i2c@{self.num}/{self.sensor.name}@10"

    def properties(self) -> dict[str, Any]:
        """libcamera's camera properties."""
        s = self.sensor
        cell_nm = round(s.optics.pixel_size_um * 1000)
        return {"Model": s.name, "Location": 2, "Rotation": 0, "PixelArraySize": (s.active_width, s.active_height),
                "PixelArrayActiveAreas": [(0, 0, s.active_width, s.active_height)], "UnitCellSize": (cell_nm, cell_nm),
                "ColorFilterArrangement": CFA_CODES.get(s.bayer_order, 0),
                "ScalerCropMaximum": self.crop_limits(), "SystemDevices": (), "SensorSensitivity": 1.0}

    def crop_limits(self, mode: SensorMode | None = None) -> tuple[int, int, int, int]:
        """The part of the pixel array a mode reads (ScalerCrop's maximum), in array pixels."""
        c = self.sensor.crop(mode or self.device.spec.settings.mode)
        return (c.left, c.top, c.width, c.height)

    def controls(self) -> dict[str, tuple[Any, Any, Any]]:
        """Every control with (min, max, default), for the mode programmed now."""
        state = self.device.state
        line = ctl.line_ns(state)
        lo_f, hi_f = ctl.frame_duration_range_ns(state)
        e = self.sensor.exposure
        g = self.sensor.gain
        limits = self.crop_limits()
        out: dict[str, tuple[Any, Any, Any]] = {
            "ExposureTime": (e.min_lines * line // 1000, (hi_f - e.max_margin_lines * line) // 1000,
                             self.base.settings.exposure_ns // 1000),
            "AnalogueGain": (g.analog_min, g.analog_max, 1.0),
            "FrameDurationLimits": (lo_f // 1000, hi_f // 1000, state.spec.settings.timing.frame_period_ns // 1000),
            "ScalerCrop": ((limits[0], limits[1], 64, 64), limits, limits),
            "ExposureTimeMode": (0, 1, 0), "AnalogueGainMode": (0, 1, 0),
            **AUTO_CONTROLS}
        if self.sensor.name in FOCUS_SENSORS:
            out.update(FOCUS_CONTROLS)
        if self.sensor.name == "imx500":  # the input tensor comes with every result that has one
            out["CnnEnableInputTensor"] = (False, True, False)
        return out

    def mode_info(self, mode: RawMode) -> dict[str, Any]:
        """What ``Picamera2.sensor_modes`` lists for a mode: size, format, bit depth, fastest frame rate, crop
        and exposure limits (us)."""
        from .sensor_format import SensorFormat

        spec = dataclasses.replace(self.base, size=mode.size, pixel_format=next(iter(mode.fourccs.values())),
                                   frame_length_lines=None, line_length_pck=None, hflip=False, vflip=False)
        state = ctl.SensorState.of(spec)
        line, (lo_f, hi_f) = ctl.line_ns(state), ctl.frame_duration_range_ns(state)
        e = self.sensor.exposure
        fmt = SensorFormat(mode.format)
        return {"format": fmt, "unpacked": fmt.unpacked, "bit_depth": mode.bit_depth, "size": mode.size,
                "fps": round(1e9 / lo_f, 2), "crop_limits": self.crop_limits(mode.mode),
                "exposure_limits": (e.min_lines * line // 1000, (hi_f - e.max_margin_lines * line) // 1000,
                                    self.base.settings.exposure_ns // 1000)}

    def metadata(self, frame: Frame, spec: CameraSpec, crop: tuple[int, int, int, int]) -> dict[str, Any]:
        """libcamera's metadata of a frame (times in integer ns and us as libcamera gives them) and rollcam's
        per-row timing (``Rollcam*`` keys)."""
        s = spec.settings
        m = frame.meta
        black = round(self.sensor.noise.black_level_dn * (1 << max(16 - self.sensor.bit_depth, 0)))
        md: dict[str, Any] = {
            "SensorTimestamp": int(self.device.host_ns(frame.timestamp_ns)),
            "ExposureTime": int(frame.exposure_ns // 1000),
            "FrameDuration": int(round(s.timing.frame_period_ns / 1000)),
            "AnalogueGain": float(m.get("analog_gain", 1.0)), "DigitalGain": float(m.get("digital_gain", 1.0)),
            "SensorBlackLevels": (black,) * 4, "ScalerCrop": crop,
            "ColourGains": tuple(self.extra.get("ColourGains", (1.0, 1.0))), "ColourTemperature": 5000,
            "Lux": 400.0, "AeLocked": True, "FocusFoM": 0, "SensorTemperature": 25.0,
            "RollcamSequence": int(frame.sequence), "RollcamDeviceTimestamp": int(frame.timestamp_ns),
            "RollcamLineTime": int(frame.line_time_ns), "RollcamReadout": frame.readout.value,
            "RollcamShutter": frame.shutter, "RollcamExposureTimeNs": int(frame.exposure_ns),
            "RollcamFrameDurationNs": int(s.timing.frame_period_ns),
        }
        cnn = self.cnn
        if cnn is None and spec.insensor is not None:  # a network named in the source, no IMX500 object
            cnn = _cnn.CnnProgram(spec.insensor.network, spec.insensor.network, spec.insensor.max_size)
        if cnn is not None:
            c = self.sensor.crop(s.mode)
            md.update(_cnn.cnn_metadata(cnn, frame, (c.left, c.top, c.width, c.height),
                                        (self.sensor.active_width, self.sensor.active_height)))
        for name in ("AeEnable", "AwbEnable", "LensPosition", "AfMode"):
            if name in self.extra:
                md[name] = self.extra[name]
        if self.sensor.name in FOCUS_SENSORS:
            md.setdefault("LensPosition", 1.0)
            md.update(self._focus_state())
        return md

    def _focus_state(self) -> dict[str, int]:
        """libcamera's AfState and AfPauseState of a frame. Every scene is in focus at every lens position
        (rollcam renders no depth of field), so a scan ends at once: Continuous mode is Focused (Paused while
        paused), and an Auto cycle started with ``AfTrigger`` Start is Focused from the next frame."""
        mode, trigger = int(self.extra.get("AfMode", 0)), self.extra.pop("AfTrigger", None)
        if mode != 1:
            self.af_state = 0 if mode == 0 else 2
        elif trigger is not None:
            self.af_state = 2 if int(trigger) == 0 else 0
        paused = mode == 2 and int(self.extra.get("AfPause", 2)) in (0, 1)
        return {"AfState": self.af_state, "AfPauseState": 2 if paused else 0}

    def select_mode(self, bit_depth: int, output_size: tuple[int, int]) -> RawMode:
        """The mode libcamera's Raspberry Pi pipeline would pick for this bit depth and size (its scoring: size
        below asked for costs double, aspect ratio much more, bit depth most)."""
        def score(m: RawMode) -> float:
            def term(want: float, got: float) -> float:
                d = want - got
                return -d / 4 if d < 0 else d * 2
            w, h = output_size
            return (term(w, m.size[0]) + term(h, m.size[1]) + 1500 * term(w / h, m.size[0] / m.size[1])
                    + 500 * abs(bit_depth - m.bit_depth))
        return min(self.modes, key=score)

    def program(self, mode: RawMode, packed: bool, hflip: bool, vflip: bool) -> str:
        """Program ``mode`` (idle only) with raw samples packed or not; returns the raw fourcc streamed."""
        fourcc = mode.fourccs.get(packed) or mode.fourccs.get(not packed)
        self.device.update(size=mode.size, pixel_format=fourcc, frame_length_lines=None, line_length_pck=None,
                           hflip=hflip, vflip=vflip, idle_only="mode")
        self.frame_limits_us, self.exposure_us, self.analogue_gain = (0, 1 << 62), 0, 0.0
        self.extra, self.scaler_crop = {}, None
        self._sync_network()
        return self.device.pixel_format

    def set_network(self, program: _cnn.CnnProgram) -> None:
        """Run ``program``'s network (``IMX500``) from the next frame, with its inference region."""
        self.cnn = program
        self._sync_network()

    def inject(self, tensor: bytes) -> int:
        """Put an input tensor in the place of the next frame's (``InSensorStage.inject``): that frame's number."""
        return self.device.inject(tensor)

    def _sync_network(self) -> None:
        if self.cnn is None:
            return
        options = {"insensor_roi": _cnn.roi_option(self.cnn, self.crop_limits(), self.device.size)}
        if self._own_network:
            options.update(self.cnn.options())
        self.device.set_options(options)

    def raw_name(self) -> str:
        """libcamera's name of the raw format streamed now (its Bayer order follows the flips)."""
        spec = self.device.spec
        return _name(sf.pixel_format(spec.output_format), spec.bayer_order)

    def apply(self, changes: dict[str, Any]) -> None:
        """Apply libcamera controls together, before the next frame (the grouped change of one request)."""
        known = self.controls()
        for name in changes:
            if name not in known:
                raise RuntimeError(f"Control {name} is not advertised by libcamera")
        sensor_side = {"ExposureTime", "AnalogueGain", "FrameDurationLimits"}
        for name, value in changes.items():
            self._set_one(name, value)
        if sensor_side & set(changes) or not changes:
            self._program_sensor()

    def _set_one(self, name: str, value: Any) -> None:
        try:
            if name == "ExposureTime":
                self.exposure_us = max(int(value), 0)
            elif name == "AnalogueGain":
                self.analogue_gain = max(float(value), 0.0)
            elif name == "FrameDurationLimits":
                lo, hi = (int(v) for v in value)
                self.frame_limits_us = (max(min(lo, hi), 1), max(lo, hi, 1))
            elif name == "ScalerCrop":
                x, y, w, h = (int(v) for v in value)
                self.scaler_crop = (x, y, max(w, 2), max(h, 2))
            else:
                self.extra[name] = value
        except (TypeError, ValueError):
            raise ValueError(f"control {name} cannot take {value!r}") from None

    def _program_sensor(self) -> None:
        dev = self.device
        with dev.lock:
            state = dev.state
            lo, hi = ctl.frame_duration_range_ns(state)
            want_lo, want_hi = (us * 1000 for us in self.frame_limits_us)
            frame = (min(max(want_lo, lo), hi), min(max(want_hi, lo), hi))
            exposure = self.exposure_us * 1000 if self.exposure_us else self.base.settings.exposure_ns
            ctl.program_exposure(state, exposure, frame)
            base_analog = ctl.linear_gain(ctl.SensorState.of(self.base), "analog")
            ctl.set_linear_gain(state, "analog", self.analogue_gain or base_analog)
            dev.reprogram(state.to_spec())
