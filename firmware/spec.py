"""``CameraSpec``: the one frozen, validated description of an emulated camera.

Sensor, output size, frame and line length, shutter, readout, exposure, gain, pixel format, sensor-model stages,
blur bound, lens (``lens``: vignetting, PSF), ISP picture steps (``picture``: sharpening, JPEG), flips, test
pattern, scene, IMU, in-sensor network (``insensor``) and injected sensor defects (``defects``): everything that
decides a frame's bytes besides the frame's sequence number and start time. It is validated once, when it is
made (``dataclasses.replace`` re-validates), and never changes; a device that is reprogrammed holds a new one.
Every front door builds or replaces it: ``from_options`` for text (``emu:`` URIs, ``rollcam emulate`` flags,
``rollcam://`` URLs, serial ``SCENE``), ``create`` for typed values, and the firmware's controls, registers,
V4L2 and UVC requests through ``rollcam.firmware.controls.SensorState``.

Gain is the linear total gain (1.0 = unity): the sensor model splits it into analog then digital gain as a
driver does; doors that speak register codes (V4L2 analogue/digital gain, the gain registers) or hundredths
(UVC) convert in ``rollcam.firmware.controls``. Exposure is a request in ns (None: 10 ms), realised in whole
lines and clamped to the frame (``settings.exposure_ns``, ``settings.clamped_exposure``).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from rollcam.common.errors import ConfigError, RollcamError
from rollcam.common.values import SERIAL
from rollcam.sim import formats as sf
from rollcam.sim.defects import SensorDefects
from rollcam.sim.hwconfig import SensorConfig, load_sensor
from rollcam.sim.imu import ImuParams
from rollcam.sim.noise import parse_stages
from rollcam.sim.optics import LensOptics
from rollcam.sim.picture import PictureSteps
from rollcam.sim.scene import Scene
from rollcam.sim.scenegen import ego_preset, make_scene
from rollcam.sim.sensor import flipped_cfa
from rollcam.sim.synthetic import MIN_FPS, StreamSettings, resolve_settings

from .imu import IMU_OPTIONS, imu_option_values, resolve_imu
from .insensor import INSENSOR_OPTIONS, InSensorConfig, insensor_option_values, load_network, resolve_insensor
from .options import MAX_BLUR_PX, MAX_EXPOSURE_US, MAX_SEED, OPTIONS, check_size, check_text, parse_options
from .pixfmt import FORMATS, raw_formats
from .traits import traits_for


@dataclass(frozen=True)
class CameraSpec:
    """An emulated camera's complete programming (see the module docstring); build it with ``create`` or
    ``from_options``, change it with ``dataclasses.replace`` or ``with_options``."""

    sensor: SensorConfig
    size: tuple[int, int] | None = None
    frame_length_lines: int | None = None
    line_length_pck: int | None = None
    shutter: str | None = None
    readout: str | None = None
    exposure_ns: int | None = None
    gain: float = 1.0
    pixel_format: str = "BGR3"
    physics: bool | None = None
    blur_px: float = 0.5
    ego_blur: str = "lines"  # a moving camera's blur: "lines" (exact samples) or "path" (sim.exposure's path blur)
    noise: frozenset[str] | None = None
    lens: LensOptics = field(default_factory=LensOptics)
    picture: PictureSteps = field(default_factory=PictureSteps)
    serial: str = SERIAL
    noise_seed: int = 0
    hflip: bool = False
    vflip: bool = False
    test_pattern: str = "none"
    scene: str = "street"
    seed: int = 0
    scene_options: tuple[tuple[str, Any], ...] = ()
    camera: str = "0"
    mount_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  # a rig camera's place: right, forward, up from camera
    mount_yaw_deg: float = 0.0  # and its turn to the right (rollcam.firmware.rig)
    imu: ImuParams | None = None
    rs_correct: str = "none"
    insensor: InSensorConfig | None = None
    defects: SensorDefects | None = None  # a fault plan's sensor defects (docs/faults.md), made by the sensor model
    settings: StreamSettings = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        _check_limits(self)
        s = resolve_settings(self.sensor, size=self.size, shutter=self.shutter, readout=self.readout,
                             exposure_ns=self.exposure_ns, gain=self.gain,
                             frame_length_lines=self.frame_length_lines, line_length_pck=self.line_length_pck)
        fix = object.__setattr__  # normalised once here, so equal programmings compare equal
        fix(self, "settings", s)
        fix(self, "size", (s.width, s.height))
        fix(self, "shutter", s.shutter)
        fix(self, "readout", s.readout.value)
        fix(self, "gain", float(self.gain))
        fix(self, "mount_m", tuple(float(v) for v in self.mount_m))
        fix(self, "mount_yaw_deg", float(self.mount_yaw_deg))
        fix(self, "pixel_format", self._base_format(self.pixel_format))
        fix(self, "scene_options", tuple(sorted(dict(self.scene_options).items())))
        if isinstance(self.insensor, InSensorConfig) and self.insensor.input is None:  # the network's own input
            fix(self, "insensor", dataclasses.replace(self.insensor, input=self.insensor.resolved_input(
                load_network(self.insensor.network))))
        _check_values(self)

    # -------------------------------------------------------------------------------------- building
    @classmethod
    def create(cls, sensor: SensorConfig | str, *, scene: Mapping[str, Any] | str | None = None,
               fps: float | None = None, **fields: Any) -> CameraSpec:
        """A spec from typed values: ``scene`` is a kind or ``{'scene': kind, 'seed': n, <kind's options>}``
        (values as text or typed, parsed by the option table), ``fps`` sets the frame length; other keywords
        are fields."""
        sensor = load_sensor(sensor) if isinstance(sensor, str) else sensor
        if "imu_values" in fields:
            fields["imu"] = resolve_imu(sensor, fields.get("imu"), fields.pop("imu_values"))
        if "insensor_values" in fields:
            fields["insensor"] = resolve_insensor(fields.get("insensor"), fields.pop("insensor_values"))
        if isinstance(scene, str):
            fields["scene"], scene = scene, None
        if scene:
            fields.update(_scene_fields(parse_options(dict(scene), "scene", ConfigError,
                                                      allowed=_SCENE_NAMES)))
        if fps is not None:
            if "frame_length_lines" in fields:
                raise ConfigError("give fps or frame_length_lines, not both")
            probe = resolve_settings(sensor, size=fields.get("size"), readout=fields.get("readout"), fps=fps,
                                     line_length_pck=fields.get("line_length_pck"))
            fields["frame_length_lines"] = probe.timing.frame_length_lines
        return cls(sensor, **fields)

    @classmethod
    def from_options(cls, sensor: SensorConfig | str, options: Mapping[str, Any], owner: str = "camera",
                     error: type[RollcamError] = ConfigError) -> CameraSpec:
        """A spec from text options named as in ``rollcam.firmware.options.OPTIONS`` (defaults: the table's);
        any problem raises ``error`` naming ``owner``."""
        values = parse_options(options, owner, error)
        try:
            sensor = load_sensor(sensor) if isinstance(sensor, str) else sensor
            return cls.create(sensor, **_fields(values))
        except ConfigError as exc:
            if error is ConfigError:
                raise
            raise error(f"{owner}: {exc}") from None

    def with_options(self, options: Mapping[str, Any], owner: str = "camera") -> CameraSpec:
        """This spec with text options changed (``SCENE KEY VALUE``): another scene kind starts from its own
        defaults (the seed and camera stay); a new fps or size resets the frame length."""
        current = {"scene": self.scene, "seed": self.seed, "camera": self.camera, **dict(self.scene_options)}
        if "scene" in options and str(options["scene"]).lower() != self.scene:
            current = {"seed": self.seed, "camera": self.camera}
        merged = {**current, **options}
        values = parse_options(merged, owner, ConfigError)
        changes = _fields(values, self)
        if "imu_values" in changes:
            changes["imu"] = resolve_imu(self.sensor, self.imu, changes.pop("imu_values"))
        if "insensor_values" in changes:
            changes["insensor"] = resolve_insensor(self.insensor, changes.pop("insensor_values"))
        fps = changes.pop("fps", None)
        if "size" in changes:
            changes.setdefault("frame_length_lines", None)
            changes.setdefault("line_length_pck", None)
        spec = dataclasses.replace(self, **changes)
        if fps is not None:
            lines = resolve_settings(self.sensor, size=spec.size, readout=spec.readout, fps=fps).timing
            spec = dataclasses.replace(spec, frame_length_lines=lines.frame_length_lines, line_length_pck=None)
        return spec

    # -------------------------------------------------------------------------------------- derived
    @property
    def raw(self) -> bool:
        """True when frames are raw sensor samples (Bayer or mono), not an ISP picture."""
        return self.pixel_format not in FORMATS and sf.pixel_format(self.pixel_format).is_raw

    @property
    def uses_physics(self) -> bool:
        """True when frames go through the sensor model (default: every format but BGR3, any stream whose
        in-sensor network reads the raw mosaic, and any with sensor defects, which the model makes)."""
        if self.physics is not None:
            return self.physics
        return (self.pixel_format != "BGR3" or (self.insensor is not None and self.insensor.input == "raw")
                or self.defects is not None)

    @property
    def output_format(self) -> str:
        """The fourcc frames carry: a raw one in the Bayer order the flips give (RG10 with hflip is GR10)."""
        return self.flipped(self.pixel_format)

    def flipped(self, fourcc: str) -> str:
        """A processed fourcc as it is; a raw one (given in the sensor's order) in the order the flips give."""
        if fourcc in FORMATS:
            return fourcc
        f = sf.pixel_format(fourcc)
        if not f.is_raw or f.cfa == "mono":
            return fourcc
        return sf.bayer_fourcc(self.bayer_order, f.bits, f.packing == "csi2")

    def device_formats(self) -> list[str]:
        """Fourccs a camera of this spec streams: the ISP's processed ones, then the sensor's raw ones in the
        Bayer order the flips give (as a Linux sensor driver enumerates them)."""
        return [*FORMATS, *(self.flipped(f) for f in raw_formats(self.sensor))]

    def resolve_format(self, fourcc: str) -> str:
        """The fourcc selecting ``fourcc`` gives (a raw one in the current Bayer order, given in either);
        ConfigError when the camera has no such format."""
        want = fourcc.ljust(4) if len(fourcc) == 3 else fourcc
        if want in FORMATS:
            return want
        for base in raw_formats(self.sensor):
            if want in (base, self.flipped(base)):
                return self.flipped(base)
        raise ConfigError(f"pixel format {fourcc!r} is not one of this {self.sensor.name} camera's "
                          f"{self.device_formats()}")

    @property
    def bayer_order(self) -> str:
        """The CFA order the output starts on with the current flips."""
        return flipped_cfa(self.sensor.bayer_order, self.size, self.hflip, self.vflip)

    def scene_values(self) -> dict[str, Any]:
        """``scene``, ``seed``, ``camera`` (when not 0) and the scene options given explicitly."""
        extra = {} if self.camera == "0" else {"camera": self.camera}
        return {"scene": self.scene, "seed": self.seed, **extra, **dict(self.scene_options)}

    def option_values(self) -> dict[str, Any]:
        """Every option of the table with the value in effect (defaults filled in, exposure as realised)."""
        s = self.settings
        scene = {n: o.default for n, o in OPTIONS.items() if o.scenes is not None and self.scene in o.scenes}
        scene.update(scene=self.scene, seed=self.seed, camera=self.camera, **dict(self.scene_options))
        return {**scene, "size": self.size, "fps": s.timing.fps, "shutter": s.shutter, "readout": s.readout.value,
                "exposure_us": s.exposure_ns / 1000, "gain": self.gain, "format": self.output_format,
                "physics": self.uses_physics, "blur_px": self.blur_px, "ego_blur": self.ego_blur,
                "serial": self.serial, **vars(self.lens),
                "noise": (parse_stages(None) if self.noise is None else self.noise) - {"quantization"},
                "noise_seed": self.noise_seed, "hflip": self.hflip, "vflip": self.vflip, **vars(self.picture),
                "test_pattern": self.test_pattern, **imu_option_values(self.sensor, self.imu),
                "rs_correct": self.rs_correct, **insensor_option_values(self.insensor)}

    def _base_format(self, fourcc: str) -> str:
        """``fourcc`` as stored: processed as is, raw in the sensor's own (unflipped) Bayer order."""
        want = fourcc.ljust(4) if len(fourcc) == 3 else fourcc
        if want in FORMATS:
            return want
        f = sf.pixel_format(want)  # ConfigError naming the fourcc when unknown
        if not f.is_raw:
            return f.fourcc
        cfa = self.sensor.bayer_order
        flipped = flipped_cfa(cfa, (self.settings.width, self.settings.height), self.hflip, self.vflip)
        if f.cfa != cfa and cfa != "mono" and f.cfa == flipped:
            f = sf.pixel_format(sf.bayer_fourcc(cfa, f.bits, f.packing == "csi2"))
        if f.cfa != cfa:
            need = "a mono format (GREY, Y10 , ...)" if cfa == "mono" else f"one of Bayer order {cfa!r}"
            raise ConfigError(f"format {fourcc!r} samples CFA {f.cfa!r}; sensor {self.sensor.name!r} delivers "
                              f"{need}")
        if f.bits > self.sensor.bit_depth:
            raise ConfigError(f"format {fourcc!r} holds {f.bits} bits, more than sensor {self.sensor.name!r}'s "
                              f"{self.sensor.bit_depth}-bit ADC")
        return f.fourcc


_SCENE_NAMES = {n for n, o in OPTIONS.items() if o.scenes is not None}
_FIELD_OF = {"format": "pixel_format", "noise": "noise", "size": "size"}


def _check_limits(spec: CameraSpec) -> None:
    """The typed fields against the option table's limits (before anything is sized from them)."""
    if spec.size is not None:
        check_size(spec.size)
        modes = [(m.width, m.height) for m in spec.sensor.modes]
        if spec.size not in modes and (spec.size[0] % 2 or spec.size[1] % 2):
            (w, h), names = spec.size, ", ".join(f"{a}x{b}" for a, b in modes)
            raise ConfigError(f"size {w}x{h} is no mode of {spec.sensor.name} ({names}) and has an odd side: a "
                              "scaled size must be even, as a Bayer tile and 4:2:0 chroma are 2 pixels")
    g = spec.sensor.gain
    max_gain = g.analog_max * g.digital_max
    slack = 1 + 1e-3  # doors that speak hundredths (UVC) round the maximum to the nearest one
    if not isinstance(spec.gain, (int, float)) or isinstance(spec.gain, bool) \
            or not 0 < spec.gain <= max_gain * slack:
        raise ConfigError(f"gain {spec.gain!r} is not in (0, {max_gain:g}] (sensor {spec.sensor.name!r}: "
                          f"analog {g.analog_max:g} x digital {g.digital_max:g})")
    if spec.exposure_ns is not None and not (isinstance(spec.exposure_ns, int)
                                             and 0 <= spec.exposure_ns <= MAX_EXPOSURE_US * 1000):
        raise ConfigError(f"exposure {spec.exposure_ns!r} ns is not a whole number in "
                          f"0..{MAX_EXPOSURE_US * 1000:.0f}")
    check_text(spec.serial, "serial number")
    check_text(spec.camera, "scene camera")


def _check_values(spec: CameraSpec) -> None:
    """The normalised spec's values that no single field decides (format and physics, frame length, seeds, the
    test pattern, the scene and its camera)."""
    if spec.shutter != spec.sensor.shutter and not traits_for(spec.sensor.name).dual_shutter:
        raise ConfigError(f"shutter {spec.shutter!r}: sensor {spec.sensor.name!r} has only a {spec.sensor.shutter} "
                          "shutter (letsroll renders either)")
    if spec.physics is False and spec.raw:
        raise ConfigError(f"pixel format {spec.pixel_format!r} needs the sensor model (physics on)")
    if not isinstance(spec.blur_px, (int, float)) or not 0 <= spec.blur_px <= MAX_BLUR_PX:
        raise ConfigError(f"blur_px must be a number in 0..{MAX_BLUR_PX:g} (0: no motion blur), got "
                          f"{spec.blur_px!r}")
    if not isinstance(spec.lens, LensOptics) or not isinstance(spec.picture, PictureSteps):
        raise ConfigError(f"lens must be a LensOptics and picture a PictureSteps, got {spec.lens!r} and "
                          f"{spec.picture!r}")
    t = spec.settings.timing
    if t.fps < MIN_FPS:
        raise ConfigError(f"a frame of {t.frame_length_lines} lines lasts {1 / t.fps:.3g} s, longer than the longest "
                          f"frame ({1 / MIN_FPS:g} s)")
    patterns = traits_for(spec.sensor.name).test_pattern_codes
    if spec.test_pattern not in patterns:
        raise ConfigError(f"test pattern {spec.test_pattern!r} is not one of {list(patterns)}")
    for name in ("noise_seed", "seed"):
        value = getattr(spec, name)
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_SEED:
            raise ConfigError(f"{name} must be a whole number in 0..{MAX_SEED}, got {value!r}")
    if spec.imu is not None and not isinstance(spec.imu, ImuParams):
        raise ConfigError(f"imu must be an ImuParams or None, got {spec.imu!r}")
    if spec.rs_correct not in ("none", "gyro"):
        raise ConfigError(f"rs_correct {spec.rs_correct!r} is not one of ['none', 'gyro']")
    if spec.rs_correct == "gyro" and (spec.imu is None or spec.raw or spec.hflip or spec.vflip):
        raise ConfigError("rs_correct=gyro needs the IMU on (imu=on), a processed format and no flips")
    if spec.insensor is not None:
        if not isinstance(spec.insensor, InSensorConfig):
            raise ConfigError(f"insensor must be an InSensorConfig or None, got {spec.insensor!r}")
        spec.insensor.resolved_input(load_network(spec.insensor.network))  # the network loads now: bad specs fail
        if spec.insensor.input == "raw" and spec.physics is False:
            raise ConfigError("insensor_input=raw needs the sensor model (physics on): the mosaic is its output")
    if spec.defects is not None:
        if not isinstance(spec.defects, SensorDefects):
            raise ConfigError(f"defects must be a SensorDefects or None, got {spec.defects!r}")
        if spec.physics is False:
            raise ConfigError(f"sensor defects ({spec.defects}) need the sensor model (physics on): it makes them")
    scene_of(spec).camera(spec.camera)  # the scene is built (and cached) now: bad options fail here


def _fields(values: dict[str, Any], current: CameraSpec | None = None) -> dict[str, Any]:
    """Parsed option values -> ``create`` keywords (a grouped field from ``current``'s, else its default, with
    the options given changed)."""
    out = _scene_fields({k: v for k, v in values.items() if k in _SCENE_NAMES})
    imu = {k: v for k, v in values.items() if k in IMU_OPTIONS}
    if imu:
        out["imu_values"] = imu
    insensor = {k: v for k, v in values.items() if k in INSENSOR_OPTIONS}
    if insensor:
        out["insensor_values"] = insensor
    for name, value in values.items():
        if name in _SCENE_NAMES or name in IMU_OPTIONS or name in INSENSOR_OPTIONS:
            continue
        if name == "exposure_us":
            out["exposure_ns"] = round(value * 1000)
        else:
            out[_FIELD_OF.get(name, name)] = value
    _group(out, {} if current is None else {"lens": current.lens, "picture": current.picture})
    return out


_GROUPS = {"lens": (LensOptics, tuple(f.name for f in dataclasses.fields(LensOptics))),
           "picture": (PictureSteps, tuple(f.name for f in dataclasses.fields(PictureSteps)))}
"""Fields that hold several options (the lens's, the ISP picture steps'), by the options they hold."""


def _group(fields: dict[str, Any], current: Mapping[str, Any]) -> None:
    """Options of a grouped field (``vignette=``, ``sharpen=``, ...) in ``fields`` replaced by that field: the
    ``current`` value (or the default) with them changed."""
    for name, (kind, members) in _GROUPS.items():
        given = {k: fields.pop(k) for k in members if k in fields}
        if given:
            fields[name] = dataclasses.replace(current.get(name) or kind(), **given)


def _scene_fields(values: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    opts = {}
    for name, value in values.items():
        if name in ("scene", "seed", "camera"):
            out[name] = value
        else:
            opts[name] = value
    out["scene_options"] = tuple(opts.items())
    return out


def scene_of(spec: CameraSpec) -> Scene:
    """The spec's scene at its output size (built once per distinct scene and size, then shared)."""
    return _build_scene(spec.scene, spec.seed, spec.scene_options, *spec.size)


@functools.lru_cache(maxsize=16)
def _build_scene(kind: str, seed: int, options: tuple[tuple[str, Any], ...], width: int, height: int) -> Scene:
    kwargs: dict[str, Any] = {"width": width, "height": height}
    for name, value in options:
        o = OPTIONS[name]
        kwargs[o.kwarg or name] = ego_preset(value) if name == "ego" else value
    return make_scene(kind, seed, **kwargs)


