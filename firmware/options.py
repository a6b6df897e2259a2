"""The emulated camera's options: one table of name, parser, default, scene kinds and one-line doc.

Every front door that names camera settings in text reads this table: the ``emu:`` URI query, the flags of
``rollcam emulate``, ``rollcam://`` URL queries and the serial ``SCENE`` command. ``parse_options`` turns
``{name: text}`` into typed values (each parser is one of ``rollcam.common.values``' or a small one here),
rejecting unknown names and options that do not apply to the chosen scene kind; ``CameraSpec.from_options``
builds the validated spec from them. Defaults are the table's, whichever door the options came through.

Every value is bounded, and the error names the bound (``LIMITS``): by the hardware where it has one (a
64-bit seed, a USB string descriptor's serial number) and otherwise by what one frame may cost in memory
and render time on an ordinary machine (``MAX_PIXELS``, ``MAX_PEDESTRIANS``, ``MAX_BLUR_PX``).
``CameraSpec`` checks its typed fields against the same limits, so doors that do not go through this table
(serial ``SIZE``, V4L2 ``S_FMT``, register writes) meet them too.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from rollcam.common.errors import ConfigError, RollcamError
from rollcam.common.values import (
    JPEG_QUALITY,
    SERIAL,
    finite_float,
    non_negative_float,
    non_negative_int,
    parse_bool,
    parse_size,
    positive_float,
    reject_unknown,
)

MAX_SIDE = 8192
"""Widest and tallest output, pixels (a 16-bit UVC wWidth holds more; the renderer's buffers do not)."""
MAX_PIXELS = 4096 * 4096
"""Most pixels in one frame: a float32 RGB frame of 16.8 MP is ~200 MB, and the renderer keeps a few."""
MAX_PEDESTRIANS = 1000
"""Most street walkers: render time grows ~N^1.7 (1,000 cost ~0.4 s a 640x480 frame on two cores;
20,000 took 64 s), and the scene is built when the option is set."""
MAX_SEED = 2**64 - 1
"""Largest scene or noise seed (a 64-bit seed, as numpy's generators take)."""
MAX_SPEED = 100.0
"""Largest street speed multiplier (100 x normal walkers is ~200 m/s)."""
MAX_VX_PX_S = 1e6
"""Fastest chart bar, px/s (it crosses the widest frame in 8 ms)."""
MAX_LEVEL = 100.0
"""Brightest flat radiance level (1 is the sensor's full range; 100 saturates any exposure)."""
MAX_EXPOSURE_US = 1e9
"""Longest exposure request, us (1000 s, the longest frame; it is clamped to the frame anyway)."""
MAX_LED_HZ = 1e6
"""Fastest LED PWM, Hz (drivers run up to a few hundred kHz; rollcam.sim.flicker.MAX_FREQ_HZ)."""
MAX_BLUR_PX = 256.0
"""Largest motion-blur bound, px (time samples per line grow with it)."""
MAX_DEVICE_NS = 2**62
"""Latest device-clock start an ``emu:`` stream may be given, ns (146 years; int64 room for its frames)."""
MAX_IMU_DENSITY = 10.0
"""Largest IMU noise density or random walk (SI units; consumer MEMS are ~1e-2 and below)."""
MAX_IMU_OFFSET_US = 1e6
"""Largest camera-IMU time offset, us (one second either way)."""
MAX_TEXT = 32
"""Longest serial number or camera name, characters (a USB iSerialNumber string is short ASCII)."""


def _num(value: float) -> str:
    return str(value) if isinstance(value, int) else f"{value:g}"


def bounded(parse: Callable[[str], Any], lo: float, hi: float) -> Callable[[str], Any]:
    """``parse`` with the result checked to lie in ``lo..hi`` (the error names both bounds)."""
    def check(text: str) -> Any:
        value = parse(text)
        if not lo <= value <= hi:
            raise ValueError(f"must be in {_num(lo)}..{_num(hi)}")
        return value
    check.__doc__ = parse.__doc__
    return check


def check_size(size: tuple[int, int]) -> tuple[int, int]:
    """``size`` (width, height) checked against ``MAX_SIDE`` and ``MAX_PIXELS`` (ConfigError naming them)."""
    w, h = size
    if w > MAX_SIDE or h > MAX_SIDE or w * h > MAX_PIXELS:
        raise ConfigError(f"size {w}x{h} is larger than the emulator renders (at most {MAX_SIDE} a side and "
                          f"{MAX_PIXELS:,} pixels)")
    return size


def check_text(value: str, what: str) -> str:
    """``value`` checked to be 1..MAX_TEXT printable ASCII characters."""
    if not value or len(value) > MAX_TEXT or not value.isascii() or not value.isprintable():
        raise ConfigError(f"{what} {value[:MAX_TEXT + 8]!r} must be 1..{MAX_TEXT} printable ASCII characters")
    return value

# The value parsers import the simulator only when they run: the table also builds the ``rollcam emulate``
# flags, and ``rollcam --help`` must not load numpy and numba.
SHUTTERS = ("rolling", "global")

SCENE_KINDS = ("street", "chart", "flat", "flicker")
LIGHT_SCENES = ("street", "flicker")  # scenes with modulated lights


def _choice(*allowed: str) -> Callable[[str], str]:
    def parse(text: str) -> str:
        word = str(text).strip().lower()
        if word not in allowed:
            raise ValueError(f"expected one of {'/'.join(allowed)}")
        return word
    return parse


def _speed(text: str) -> str:
    from rollcam.sim.scenegen import SPEED_PRESETS, parse_speed

    if parse_speed(text if str(text).lower() in SPEED_PRESETS else float(text)) > MAX_SPEED:
        raise ValueError(f"must be a preset or a multiplier in 0..{MAX_SPEED:g}")
    return str(text).lower()


def _lamp(text: str) -> str:
    from rollcam.sim.scenegen import LAMP_TYPES

    word = str(text).strip().lower()
    if word not in LAMP_TYPES:
        raise ValueError(f"expected one of {'/'.join(LAMP_TYPES)}")
    return word


def _mains(text: str) -> float:
    value = finite_float(text)
    if value not in (50.0, 60.0):
        raise ValueError("expected 50 or 60 (Hz)")
    return value


def _ego(text: str) -> str:
    from rollcam.sim.scenegen import ego_preset

    ego_preset(str(text))
    return str(text)


def _readout(text: str) -> str:
    from rollcam.sim.timing import Readout

    return Readout.parse(text).value


def _fourcc(text: str) -> str:
    text = str(text)
    return text.ljust(4) if len(text) == 3 else text


def _noise(text: str) -> frozenset[str]:
    from rollcam.sim.noise import parse_stages

    return parse_stages(str(text))


def _vector3(text: str) -> tuple[float, float, float]:
    parts = str(text).replace(" ", "").split(",")
    if len(parts) != 3:
        raise ValueError("expected three numbers x,y,z")
    return tuple(finite_float(p) for p in parts)  # type: ignore[return-value]


def _text(text: str) -> str:
    return check_text(str(text), "text")


def _size(text: str) -> tuple[int, int]:
    return check_size(parse_size(text))


_seed = bounded(non_negative_int, 0, MAX_SEED)


def _sim_bounded(parse: Callable[[str], Any], module: str, limit: str) -> Callable[[str], Any]:
    """``bounded(parse, 0, module.limit)``, the limit read from the simulator module that owns it when a value is
    parsed (so the table itself loads no numpy)."""
    def check(text: str) -> Any:
        import importlib

        return bounded(parse, 0, getattr(importlib.import_module(module), limit))(text)
    check.__doc__ = parse.__doc__
    return check


def _network(text: str) -> str | None:
    from .insensor import network_spec

    return network_spec(text)


def _accel(text: str) -> Any:
    from .insensor import accelerator

    return accelerator(text)


def _roi(text: str) -> Any:
    from .insensor import parse_roi

    return parse_roi(text)


def _tensor(text: str) -> Any:
    from .input_tensor import parse_tensor_format

    return parse_tensor_format(text)


def _insensor_output(text: str) -> str:
    from .insensor import output_mode

    return output_mode(text)


@dataclass(frozen=True)
class Option:
    """One camera option: its parser, default, the scene kinds it applies to (None: not a scene option)."""

    name: str
    parse: Callable[[str], Any]
    default: Any
    doc: str
    scenes: tuple[str, ...] | None = None
    kwarg: str | None = None  # make_scene keyword of a scene option (default: the option's name)


OPTIONS: dict[str, Option] = {o.name: o for o in (
    Option("scene", _choice(*SCENE_KINDS), "street", "scene kind: street | chart | flat | flicker (a wall under "
                                                     "one modulated lamp)", SCENE_KINDS),
    Option("seed", _seed, 0, "scene seed (integer >= 0)", SCENE_KINDS),
    Option("camera", _text, "0", "scene camera: index or name", SCENE_KINDS),
    Option("time", _choice("dawn", "morning", "noon", "afternoon", "dusk", "night"), "noon",
           "street: dawn | morning | noon | afternoon | dusk | night", ("street",), "time_of_day"),
    Option("lamps", _choice("auto", "on", "off"), "auto", "street: street lamps and LED signs (modulated light): "
                                                         "auto (on at dusk and night) | on | off", ("street",)),
    Option("lamp", _lamp, "sodium", "street lamp / flicker lamp type: incandescent | halogen | fluorescent | "
                                    "sodium | led (PWM)", LIGHT_SCENES),
    Option("mains_hz", _mains, 50.0, "mains frequency of the lamps, Hz: 50 | 60 (light at twice that)",
           LIGHT_SCENES),
    Option("lamp_depth", bounded(non_negative_float, 0.0, 1.0), None,
           "lamps' modulation depth 0..1 (default: the lamp type's)", LIGHT_SCENES),
    Option("led_hz", bounded(positive_float, 0.0, MAX_LED_HZ), 400.0, "PWM frequency of LED signs and LED "
                                                                     "lamps, Hz", LIGHT_SCENES),
    Option("led_duty", bounded(positive_float, 0.0, 1.0), 0.5, "PWM duty (on-fraction) of LEDs, 0..1",
           LIGHT_SCENES),
    Option("led_phase", bounded(non_negative_float, 0.0, 1.0), 0.0, "PWM phase of LEDs at device time 0, cycles",
           LIGHT_SCENES),
    Option("speed", _speed, "normal", "street: static | normal | fast | a multiplier", ("street",)),
    Option("pedestrians", bounded(non_negative_int, 0, MAX_PEDESTRIANS), 20, "street: number of walkers",
           ("street",), "n_pedestrians"),
    Option("ego", _ego, "none", "street: camera motion none | pan | walk | vehicle | drone | calib", ("street",)),
    Option("props", parse_bool, False, "street: parked cars, trees, lamp poles, signs, benches and bins (scenery: "
                                       "they hide walkers, no truth records): on | off", ("street",)),
    Option("shadows", parse_bool, True, "street: the walkers' shadows on the ground (contact; the sun's in daylight): "
                                        "on | off",
           ("street",)),
    Option("vx", bounded(finite_float, -MAX_VX_PX_S, MAX_VX_PX_S), 2000.0, "chart: bar speed, px/s",
           ("chart",), "vx_px_s"),
    Option("level", bounded(non_negative_float, 0.0, MAX_LEVEL), 0.5,
           "flat, flicker: (mean) radiance level (0..1 is the sensor's range)", ("flat", "flicker")),
    Option("size", _size, None, "output WxH (default: the sensor's default mode; another, even size is "
                                     "a rescaled readout)"),
    Option("fps", positive_float, None, "frame rate: sets the frame length (default: the mode's); above the "
                                        "sensor's maximum for the size is an error"),
    Option("shutter", _choice(*SHUTTERS), None, "rolling | global (default: the sensor's)"),
    Option("readout", _readout, None, "readout direction tb | bt | lr | rl (default: the sensor's)"),
    Option("exposure_us", bounded(non_negative_float, 0.0, MAX_EXPOSURE_US), None,
           "exposure in us, whole lines, clamped to the frame (default: 10 ms)"),
    Option("gain", positive_float, 1.0, "linear total gain (analog first, then digital, as drivers split it)"),
    Option("format", _fourcc, "BGR3", "pixel format: BGR3 | YUYV | UYVY | NV12 | YU12 | RGB3 | XR24 | GREY | MJPG "
                                      "or a raw fourcc of the sensor (RG10, pRAA, Y10, ...)"),
    Option("physics", parse_bool, None, "sensor model (exposure integration, EMVA noise, ADC; processed formats "
                                        "through the preview ISP): default on for every format but BGR3 (the "
                                        "clean render; physics=on gives it the sensor's noise)"),
    Option("blur_px", bounded(non_negative_float, 0.0, MAX_BLUR_PX), 0.5,
           "sensor model: motion-blur bound in px (0: mid-exposure only)"),
    Option("ego_blur", _choice("lines", "path"), "lines",
           "sensor model, moving camera: lines (whole-line samples, the exact method) | path (one render blurred "
           "along each pixel's image path: 1.6-2.2x less CPU, error per ego preset in docs/sensor-model.md)"),
    Option("noise", _noise, None, "sensor model: on | off | comma list of shot, dark, read, dsnu, prnu, "
                                  "saturation (default: on)"),
    Option("vignette", _sim_bounded(non_negative_float, "rollcam.sim.optics", "MAX_VIGNETTE"), 0.0,
           "lens: fraction of the light lost at the image corners, cos^4 falloff (0: none; 0.3: a phone lens)"),
    Option("lens_blur_px", _sim_bounded(non_negative_float, "rollcam.sim.optics", "MAX_BLUR_SIGMA_PX"), 0.0,
           "lens: Gaussian point-spread function, sigma in px (0: a perfect lens)"),
    Option("defocus_px", _sim_bounded(non_negative_float, "rollcam.sim.optics", "MAX_DEFOCUS_PX"), 0.0,
           "lens: defocus disc (circle of confusion) radius in px (0: in focus)"),
    Option("sharpen", _sim_bounded(non_negative_float, "rollcam.sim.isp", "MAX_SHARPEN"), 0.0,
           "ISP: unsharp-mask amount on the luma, processed formats (0: off; ~1: a phone's ISP)"),
    Option("jpeg_quality", bounded(non_negative_int, 0, 100), 0,
           "ISP: JPEG compression left in the picture at quality 1..100, processed formats (0: off); with "
           f"format=MJPG the encoder's quality (0: {JPEG_QUALITY})"),
    Option("serial", _text, SERIAL, "device serial number (fixes the DSNU/PRNU patterns)"),
    Option("noise_seed", _seed, 0, "temporal noise seed"),
    Option("mount_m", _vector3, (0.0, 0.0, 0.0), "the camera moved from the scene camera, as one camera of a "
                                                   "rig: right,forward,up in m (docs/rigs.md)"),
    Option("mount_yaw_deg", finite_float, 0.0, "the camera turned right from the scene camera, degrees (a rig's)"),
    Option("hflip", parse_bool, False, "mirror left-right (raw: the Bayer order changes as the sensor's does)"),
    Option("vflip", parse_bool, False, "flip top-bottom: the scene is read bottom-up, first line still first"),
    Option("imu", parse_bool, False, "IMU beside the camera (gyro + accelerometer on the device clock): on | off; "
                                     "any imu_ option turns it on"),
    Option("imu_rate", bounded(non_negative_int, 100, 2000), None, "IMU rate, Hz 100..2000 (default: the "
                                                                    "hw_config's imu section, else 400)"),
    Option("imu_gyro_noise", bounded(non_negative_float, 0.0, MAX_IMU_DENSITY), None,
           "gyro white-noise density, rad/s/sqrt(Hz) (Kalibr gyroscope_noise_density)"),
    Option("imu_gyro_walk", bounded(non_negative_float, 0.0, MAX_IMU_DENSITY), None,
           "gyro bias random walk, rad/s^2/sqrt(Hz) (Kalibr gyroscope_random_walk)"),
    Option("imu_accel_noise", bounded(non_negative_float, 0.0, MAX_IMU_DENSITY), None,
           "accelerometer white-noise density, m/s^2/sqrt(Hz) (Kalibr accelerometer_noise_density)"),
    Option("imu_accel_walk", bounded(non_negative_float, 0.0, MAX_IMU_DENSITY), None,
           "accelerometer bias random walk, m/s^3/sqrt(Hz) (Kalibr accelerometer_random_walk)"),
    Option("imu_offset_us", bounded(finite_float, -MAX_IMU_OFFSET_US, MAX_IMU_OFFSET_US), None,
           "camera-IMU time offset, us (Kalibr timeshift_cam_imu: t_imu = t_cam + offset)"),
    Option("imu_rotation_deg", _vector3, None, "R_cam_imu as a rotation vector x,y,z in degrees"),
    Option("imu_translation_m", _vector3, None, "the IMU's origin in camera coordinates x,y,z, m"),
    Option("rs_correct", _choice("none", "gyro"), "none", "ISP rolling-shutter correction: none | gyro (per-row "
                                                          "rotational unwarp from the IMU; processed formats)"),
    Option("insensor", _network, "none", "in-sensor network, run on the chip on every frame it has time for: a "
                                          "detector spec (personnet-raw, personnet, onnx:PATH, hog) or none"),
    Option("insensor_input", _choice("raw", "isp"), None, "in-sensor network input: raw (the mosaic, no ISP) | "
                                                         "isp (the ISP's picture) (default: the network's)"),
    Option("insensor_size", _size, None, "largest in-sensor network input WxH; larger frames are binned by a whole "
                                         "factor (default: 640x640)"),
    Option("insensor_roi", _roi, None, "in-sensor network input region x,y,w,h in frame pixels (default: the whole "
                                       "frame); boxes still come back in frame pixels"),
    Option("insensor_tensor", _tensor, None, "in-sensor network input tensor, made by the IMX500's ISP from the "
                                             "picture: none | WxH[,rgb|bgr][,uint8|int8][,crop][,norm=A/B/C]"
                                             "[,div=A/B/C] (docs/insensor.md)"),
    Option("insensor_accel", _accel, "imx500", "in-sensor accelerator: imx500 | a throughput in GMAC/s (latency = "
                                               "the network's MACs / throughput)"),
    Option("insensor_output", _insensor_output, "frame", "what leaves the chip: frame (image and results, also "
                                                         "frame+meta) | meta (results only)"),
    Option("test_pattern", _text, "none", "sensor test pattern instead of the scene: none | bars | solid | "
                                          "fade_bars | pn9 | walking_ones (as the sensor has them)"),
)}
"""The camera options, by name."""


SCENE_OPTIONS = {name: o for name, o in OPTIONS.items() if o.scenes is not None}
"""The options that describe the scene (``SCENE KEY VALUE`` on the serial line)."""


def parse_options(options: Mapping[str, Any], owner: str, error: type[RollcamError] = ConfigError,
                  allowed: set[str] | None = None) -> dict[str, Any]:
    """``{name: text}`` -> ``{name: value}`` through the table; unknown names, bad values and scene options of
    another scene kind raise ``error`` naming ``owner`` and the option. Values that are not text are first
    written as text, so every door goes through the same parser."""
    reject_unknown(dict(options), set(OPTIONS) if allowed is None else allowed, owner, error)
    out = {name: _parse(name, raw, owner, error) for name, raw in options.items()}
    kind = out.get("scene", OPTIONS["scene"].default)
    misplaced = sorted(n for n in out if OPTIONS[n].scenes is not None and kind not in OPTIONS[n].scenes)
    if misplaced:
        what = f"option {misplaced[0]!r} does" if len(misplaced) == 1 else f"options {misplaced} do"
        raise error(f"{owner}: {what} not apply to scene={kind!r} (its options: "
                    f"{sorted(n for n, o in SCENE_OPTIONS.items() if kind in o.scenes)})")
    return out


def _parse(name: str, raw: Any, owner: str, error: type[RollcamError]) -> Any:
    try:
        return OPTIONS[name].parse(raw if isinstance(raw, str) else as_text(raw))
    except (TypeError, ValueError, ConfigError) as exc:
        raise error(f"{owner}: option {name}={raw!r} is invalid ({exc})") from None


def as_text(value: Any) -> str:
    """An option value as the text its parser reads back."""
    if isinstance(value, bool):
        return "on" if value else "off"
    if isinstance(value, tuple) and len(value) == 2:
        return f"{value[0]}x{value[1]}"
    if isinstance(value, tuple) and len(value) == 3:
        return ",".join(as_text(float(v)) for v in value)
    if isinstance(value, (set, frozenset)):
        return ",".join(sorted(value)) or "off"
    if isinstance(value, float):
        short = f"{value:.6g}"
        return short if float(short) == value else repr(value)  # never round a value away
    return str(value).strip()


def option_help() -> list[tuple[str, str, str]]:
    """(name, default, doc) of every option, for usage text and documentation."""
    return [(o.name, "" if o.default is None else as_text(o.default), o.doc) for o in OPTIONS.values()]
