"""Configurations: picamera2's ``create_*_configuration`` dictionaries, their checks, and mode selection.

``ConfigMixin`` is the part of ``Picamera2`` that makes and checks configurations; ``resolve`` turns one into
what the camera streams: the sensor mode (libcamera's scoring of size, aspect ratio and bit depth), the raw
format in the flips' Bayer order, and each stream's stride and frame size.
"""

from __future__ import annotations

import copy
from typing import Any

import libcamera

from . import formats
from ._isp import SUPPORTED, stride_and_size
from .configuration import CameraConfiguration
from .sensor_format import SensorFormat

_STREAM_KEYS = ("format", "size", "stride", "preserve_ar")
_RAW_IGNORED = ("bit_depth", "crop_limits", "exposure_limits", "fps", "unpacked")  # sensor_modes entries
_DEFAULT_CONTROLS = {"preview": (3, (100, 83333)), "still": (2, (100, 1_000_000 * 1000)), "video": (1, (33333, 33333))}


def _stream(defaults: dict[str, Any], updates: dict[str, Any] | None, ignore: tuple[str, ...] = ()) -> Any:
    if updates is None:
        return None
    out = dict(defaults)
    for key, value in updates.items():
        if key in _STREAM_KEYS:
            out[key] = str(value) if isinstance(value, SensorFormat) else value
        elif key not in ignore:
            raise ValueError(f"Bad key {key!r}: valid stream configuration keys are {_STREAM_KEYS}")
    return out


def _align_even(stream: dict[str, Any]) -> None:
    w, h = stream["size"]
    stream["size"] = (w - w % 2, h - h % 2)


class ConfigMixin:
    """``create_preview_configuration``, ``create_still_configuration``, ``create_video_configuration``,
    ``align_configuration``, ``check_camera_config`` and the configuration's resolution into a mode."""

    _cam: Any
    camera_controls: dict[str, Any]

    def _create(self, use_case: str, main_defaults: dict[str, Any], main: Any, lores: Any, raw: Any,
                transform: Any, colour_space: Any, buffer_count: int, controls: dict[str, Any], display: Any,
                encode: Any, queue: bool, sensor: Any) -> dict[str, Any]:
        if self._cam is None:
            raise RuntimeError("Camera not opened")
        main_cfg = _stream(main_defaults, main)
        _align_even(main_cfg)
        lores_cfg = _stream({"format": "YUV420", "size": main_cfg["size"], "preserve_ar": False}, lores)
        if lores_cfg is not None:
            _align_even(lores_cfg)
        raw_cfg = _stream({"format": self.sensor_format, "size": main_cfg["size"]}, raw, _RAW_IGNORED)
        nr, limits = _DEFAULT_CONTROLS[use_case]
        controls = {"NoiseReductionMode": nr, "FrameDurationLimits": limits, **(controls or {})}
        if colour_space is None:
            small = main_cfg["size"][0] < 1280 or main_cfg["size"][1] < 720
            colour_space = libcamera.ColorSpace.Smpte170m() if small else libcamera.ColorSpace.Rec709()
        config = {"use_case": use_case, "transform": transform, "colour_space": colour_space,
                  "buffer_count": buffer_count, "queue": queue, "main": main_cfg, "lores": lores_cfg,
                  "raw": raw_cfg, "controls": controls, "sensor": sensor}
        for role, name in (("display", display), ("encode", encode)):
            if name is not None and config.get(name) is None:
                raise RuntimeError(f"{role.capitalize()} stream {name} was not defined")
            config[role] = name
        return config

    def create_preview_configuration(self, main: Any = None, lores: Any = None, raw: Any = ...,
                                     transform: Any = None, colour_space: Any = None, buffer_count: int = 4,
                                     controls: Any = None, display: Any = "main", encode: Any = "main",
                                     queue: bool = True, sensor: Any = None, use_case: str = "preview") -> dict:
        """A configuration for preview: main 640x480 XBGR8888, 4 buffers, 12 fps or faster."""
        return self._create("preview", {"format": "XBGR8888", "size": (640, 480), "preserve_ar": True},
                            {} if main is None else main, lores, {} if raw is ... else raw,
                            transform or libcamera.Transform(), colour_space or libcamera.ColorSpace.Sycc(),
                            buffer_count, controls, display, encode, queue, {} if sensor is None else sensor)

    def create_still_configuration(self, main: Any = None, lores: Any = None, raw: Any = ...,
                                   transform: Any = None, colour_space: Any = None, buffer_count: int = 1,
                                   controls: Any = None, display: Any = None, encode: Any = None,
                                   queue: bool = True, sensor: Any = None, use_case: str = "still") -> dict:
        """A configuration for stills: main at the full sensor resolution, BGR888, 1 buffer."""
        return self._create("still", {"format": "BGR888", "size": self.sensor_resolution, "preserve_ar": True},
                            {} if main is None else main, lores, {} if raw is ... else raw,
                            transform or libcamera.Transform(), colour_space or libcamera.ColorSpace.Sycc(),
                            buffer_count, controls, display, encode, queue, {} if sensor is None else sensor)

    def create_video_configuration(self, main: Any = None, lores: Any = None, raw: Any = ...,
                                   transform: Any = None, colour_space: Any = None, buffer_count: int = 6,
                                   controls: Any = None, display: Any = "main", encode: Any = "main",
                                   queue: bool = True, sensor: Any = None, use_case: str = "video") -> dict:
        """A configuration for video: main 1280x720 XBGR8888, 6 buffers, 30 fps."""
        return self._create("video", {"format": "XBGR8888", "size": (1280, 720), "preserve_ar": True},
                            {} if main is None else main, lores, {} if raw is ... else raw,
                            transform or libcamera.Transform(), colour_space, buffer_count, controls, display,
                            encode, queue, {} if sensor is None else sensor)

    @staticmethod
    def align_configuration(config: dict[str, Any], optimal: bool = True) -> None:
        """Align main and lores sizes as the ISP wants them (see ``StreamConfiguration.align``)."""
        from .configuration import StreamConfiguration

        for name in ("main", "lores"):
            if config.get(name) is not None:
                s = StreamConfiguration(config[name])
                s.align(optimal)
                config[name]["size"] = s.size

    def check_stream_config(self, stream_config: Any, name: str) -> None:
        """RuntimeError (picamera2's messages) unless the stream is well formed."""
        if type(stream_config) is not dict:
            raise RuntimeError(name + " stream should be a dictionary")
        for key in ("format", "size"):
            if key not in stream_config:
                raise RuntimeError(f"{key} not found in {name} stream")
        fmt = stream_config["format"]
        if type(fmt) is not str:
            raise RuntimeError("format in " + name + " stream should be a string")
        if name == "raw":
            if not formats.is_raw(fmt):
                raise RuntimeError("Unrecognised raw format " + fmt)
        elif not formats.is_YUV(fmt) and not formats.is_RGB(fmt):
            raise RuntimeError("Bad format " + fmt + " in stream " + name)
        elif fmt not in SUPPORTED:
            raise RuntimeError(f"Format {fmt} in stream {name} is not supported by rollcam's emulated ISP "
                               f"(supported: {sorted(SUPPORTED)})")
        size = stream_config["size"]
        if type(size) is not tuple or len(size) != 2:
            raise RuntimeError("size in " + name + " stream should be (width, height)")
        if not all(isinstance(v, int) and v > 0 for v in size):
            raise RuntimeError(f"size {size!r} in {name} stream should be two positive integers")
        if size[0] % 2 or size[1] % 2:
            raise RuntimeError("width and height should be even")
        if name != "raw":
            aw, ah = self.camera_properties["PixelArraySize"]
            if size[0] > aw or size[1] > ah:
                raise RuntimeError(f"size {size!r} in {name} stream exceeds the sensor's pixel array {aw}x{ah}")

    def check_camera_config(self, camera_config: dict[str, Any]) -> None:
        """RuntimeError (picamera2's messages) unless the whole configuration is well formed."""
        for name in ("colour_space", "transform", "main", "lores", "raw"):
            if name not in camera_config:
                raise RuntimeError(f"{name!r} key expected in camera configuration")
        if not isinstance(camera_config["colour_space"], libcamera.ColorSpace):
            raise RuntimeError("Colour space has incorrect type")
        if not isinstance(camera_config["transform"], libcamera.Transform):
            raise RuntimeError("Transform has incorrect type")
        sensor = camera_config.get("sensor")
        if sensor:
            bad = set(sensor) - {"bit_depth", "output_size"}
            if bad:
                raise RuntimeError(f"Unexpected keys {bad} in sensor configuration")
        self.check_stream_config(camera_config["main"], "main")
        if camera_config["lores"] is not None:
            self.check_stream_config(camera_config["lores"], "lores")
            (mw, mh), (lw, lh) = camera_config["main"]["size"], camera_config["lores"]["size"]
            if lw > mw or lh > mh:
                raise RuntimeError("lores stream dimensions may not exceed main stream")
            if not formats.is_YUV(camera_config["lores"]["format"]):
                raise RuntimeError("lores stream must be YUV")
        if camera_config["raw"] is not None:
            self.check_stream_config(camera_config["raw"], "raw")

    def _resolve(self, camera_config: Any) -> dict[str, Any]:
        """A configuration (name, dict or CameraConfiguration) checked and filled in as the camera will run
        it; programs the sensor mode."""
        if isinstance(camera_config, str):
            camera_config = getattr(self, f"{camera_config}_configuration", None) or self.preview_configuration
        if isinstance(camera_config, CameraConfiguration):
            camera_config = camera_config.make_dict()
        elif isinstance(camera_config, dict):
            camera_config = copy.deepcopy({k: v for k, v in camera_config.items() if k != "controls"}) | {
                "controls": camera_config.get("controls")}
        else:
            raise TypeError("Invalid type for `camera_config` given")
        raw = camera_config.get("raw")
        if raw is not None:
            raw.setdefault("format", None)
            raw.setdefault("size", None)
            raw["format"] = raw["format"] or self.sensor_format
            raw["size"] = raw["size"] or camera_config["main"]["size"]
        self.check_camera_config(camera_config)
        sensor = camera_config.get("sensor") or {}
        bit_depth = sensor.get("bit_depth") or SensorFormat(raw["format"] if raw else self.sensor_format).bit_depth
        output_size = sensor.get("output_size") or (raw["size"] if raw else camera_config["main"]["size"])
        mode = self._cam.select_mode(int(bit_depth), tuple(output_size))
        packed = SensorFormat(raw["format"]).packing == "CSI2P" if raw else True
        t = camera_config["transform"]
        fourcc = self._cam.program(mode, packed, t.hflip, t.vflip)
        if raw is not None:
            raw.update(format=self._cam.raw_name(), size=mode.size)
        for name in ("main", "lores", "raw"):
            s = camera_config.get(name)
            if s is not None:
                s["stride"], s["framesize"] = stride_and_size(s["format"], s["size"], fourcc if name == "raw" else None)
        camera_config["sensor"] = {"bit_depth": mode.bit_depth, "output_size": mode.size}
        return camera_config
