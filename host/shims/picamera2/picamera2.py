"""``Picamera2``: picamera2's camera class on an emulated Raspberry Pi camera (``rollcam.firmware``).

A script written for a Pi runs unchanged: the camera (``Picamera2(camera_num)``) is the ``FirmwareCamera`` of
the ``camera_num``-th source of ``ROLLCAM_PICAMERA2`` (``_camera``), configured with picamera2's
configurations (``_configs``), streaming in real time on its own thread (``_engine``) through an emulated
ISP (``_isp``), captured with picamera2's calls (``_capture``). See docs/picamera2.md for what is covered.
"""

from __future__ import annotations

import atexit
import enum
import logging
import sys
import threading
from types import SimpleNamespace
from typing import Any

import libcamera

from . import formats, tuning
from ._camera import PiCamera, sources
from ._capture import CaptureMixin
from ._configs import ConfigMixin
from ._engine import Engine, RequestQueue
from ._helpers import Helpers
from ._isp import aspect_crop, crop_pixels, isp_picture, stream_arrays
from ._open import OPEN, OPEN_LOCK
from ._record import RecordMixin
from .allocators import DmaAllocator
from .configuration import CameraConfiguration
from .controls import Controls
from .platform import Platform
from .request import CompletedRequest

_log = logging.getLogger("picamera2")


def close_all() -> None:
    """Close every camera this process has open (rollcam's extra; the pytest fixture calls it)."""
    with OPEN_LOCK:
        cams = list(OPEN.values())
    for cam in cams:
        cam.close()


class Preview(enum.Enum):
    """Preview kinds; rollcam shows none (every kind runs as NULL: no window)."""

    NULL = 0
    DRM = 1
    QT = 2
    QTGL = 3


class Picamera2(ConfigMixin, CaptureMixin, RecordMixin):
    """One emulated camera, opened for this process until ``close()``."""

    DEBUG, INFO, WARNING, ERROR, CRITICAL = (logging.DEBUG, logging.INFO, logging.WARNING, logging.ERROR,
                                             logging.CRITICAL)
    platform = Platform.VC4

    load_tuning_file = staticmethod(tuning.load_tuning_file)
    find_tuning_algo = staticmethod(tuning.find_tuning_algo)

    @staticmethod
    def set_logging(level: int = logging.WARNING, output: Any = sys.stderr, msg: str | None = None) -> None:
        """Send the ``picamera2`` logger's messages of ``level`` and above to ``output`` (picamera2's helper for
        standalone scripts)."""
        logger = logging.getLogger("picamera2")
        handler = logging.StreamHandler(output)
        handler.setFormatter(logging.Formatter(msg or "%(name)s %(levelname)s: %(message)s"))
        logger.setLevel(level)
        logger.handlers = [handler]

    @staticmethod
    def global_camera_info() -> list[dict[str, Any]]:
        """Model, Location, Rotation, Id and Num of every emulated camera."""
        from ._camera import spec_of

        out = []
        for num, source in enumerate(sources()):
            name = spec_of(source).sensor.name
            out.append({"Model": name, "Location": 2, "Rotation": 0,
                        "Id": f"/base/soc/i2c0mux/i2c@{num}/{name}@10", "Num": num})
        return out

    def __init__(self, camera_num: int = 0, verbose_console: Any = None, tuning: Any = None,
                 allocator: Any = None) -> None:
        self.is_open, self.started, self._cam, self._engine, self._queue = False, False, None, None, None
        self._state = threading.Condition()  # captures made before start() wait on it
        self._jobs: set[Any] = set()
        found = sources()
        if not isinstance(camera_num, int) or not 0 <= camera_num < len(found):
            raise IndexError(f"list index out of range (camera {camera_num!r} of {len(found)} emulated)")
        with OPEN_LOCK:
            if camera_num in OPEN:
                raise RuntimeError("Camera __init__ sequence did not complete.") from RuntimeError(
                    f"Failed to acquire camera {camera_num}: Device or resource busy")
            OPEN[camera_num] = self
        try:
            self._cam = PiCamera(found[camera_num], camera_num)
        except Exception as exc:
            with OPEN_LOCK:
                OPEN.pop(camera_num, None)
            raise RuntimeError("Camera __init__ sequence did not complete.") from exc
        self.camera_idx, self.is_open = camera_num, True
        self.camera_config: dict[str, Any] = {}
        self.options: dict[str, Any] = {}
        self.pre_callback = self.post_callback = None
        self._init_recording()
        self.helpers = Helpers(self)
        self.overlay = None
        self.title_fields: list[str] = []  # metadata fields a preview window's title shows (no window here)
        self.allocator = allocator if allocator is not None else DmaAllocator()
        self.controls = Controls(self)
        self._lock = threading.RLock()
        native = max(self._cam.modes, key=lambda m: (m.size[0] * m.size[1], m.bit_depth))
        self.sensor_resolution, self.sensor_format = native.size, native.format
        self._make_named_configurations()
        atexit.register(self.close)

    def _make_named_configurations(self) -> None:
        # Raw streams without a size or format: configure() fills them in from the main stream then.
        for name in ("preview", "still", "video"):
            config = CameraConfiguration(getattr(self, f"create_{name}_configuration")(), self)
            config.enable_raw()
            setattr(self, f"{name}_configuration", config)

    def __setattr__(self, name: str, value: Any) -> None:
        if name in ("preview_configuration", "still_configuration", "video_configuration"):
            value = CameraConfiguration(value, self)
        super().__setattr__(name, value)

    def __repr__(self) -> str:
        state = "started" if self.started else "open" if self.is_open else "closed"
        return f"<Picamera2 {self.camera_idx if self.is_open else '-'} {self._cam.sensor.name if self._cam else ''} " \
               f"{state}>"

    def __enter__(self) -> Picamera2:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        if getattr(self, "is_open", False):
            self.close()

    # ------------------------------------------------------------------------------------ description
    @property
    def camera_properties(self) -> dict[str, Any]:
        """libcamera's properties: Model, PixelArraySize, ColorFilterArrangement, UnitCellSize, ..."""
        return {} if self._cam is None else self._cam.properties()

    @property
    def camera_controls(self) -> dict[str, tuple[Any, Any, Any]]:
        """Every control with (min, max, default) for the mode configured now."""
        return {} if self._cam is None else self._cam.controls()

    @property
    def sensor_modes(self) -> list[dict[str, Any]]:
        """The sensor's raw modes: format, unpacked, bit_depth, size, fps, crop_limits, exposure_limits."""
        return [self._cam.mode_info(m) for m in self._cam.modes]

    @property
    def libcamera_config(self) -> Any:
        """The configured streams as libcamera holds them: ``libcamera_config.at(i)`` (``main_index``, ...)
        has ``size``, ``stride``, ``pixel_format`` and ``color_space`` (an RGB stream's is the headline one
        with no Y'CbCr encoding and full range; the raw stream's is Raw)."""
        streams = []
        for name in ("main", "lores", "raw"):
            c = self.camera_config.get(name) if self.camera_config else None
            if c is None:
                continue
            space = libcamera.ColorSpace(self.camera_config["colour_space"])
            if name == "raw":
                space = libcamera.ColorSpace.Raw()
            elif formats.is_RGB(c["format"]):
                space.ycbcrEncoding, space.range = space.YcbcrEncoding.Null, space.Range.Full
            streams.append(SimpleNamespace(size=libcamera.Size(*c["size"]), stride=c.get("stride"),
                                           pixel_format=str(c["format"]), color_space=space))
        return SimpleNamespace(at=streams.__getitem__, size=lambda: len(streams))

    @property
    def main_index(self) -> int:
        """The main stream's index among the configured streams (libcamera's order: main, lores, raw)."""
        return 0

    @property
    def lores_index(self) -> int:
        """The lores stream's index, -1 when there is none."""
        return 1 if self.camera_config.get("lores") is not None else -1

    @property
    def raw_index(self) -> int:
        """The raw stream's index, -1 when there is none."""
        if self.camera_config.get("raw") is None:
            return -1
        return 2 if self.camera_config.get("lores") is not None else 1

    @property
    def camera(self) -> Any:
        """The camera behind this object (libcamera's ``Camera`` on a Pi; here the emulated one)."""
        return self._cam

    @property
    def rollcam_device(self) -> Any:
        """The ``rollcam.firmware.FirmwareCamera`` behind this camera (rollcam's extra): its controls and spec
        are what every other door of the device reads."""
        return self._cam.device

    @property
    def is_mono(self) -> bool:
        """True for a monochrome sensor."""
        return self._cam.sensor.bayer_order == "mono"

    def camera_configuration(self) -> dict[str, Any]:
        """The configuration in effect."""
        return self.camera_config

    def stream_configuration(self, name: str = "main") -> dict[str, Any]:
        """The named stream's configuration in effect."""
        return self.camera_config[name]

    # ------------------------------------------------------------------------------------ life cycle
    def configure(self, camera_config: Any = None) -> None:
        """Configure (a name: 'preview', 'still', 'video'; a dict; or a CameraConfiguration); camera stopped."""
        if not self.is_open:
            raise RuntimeError("Camera not opened")
        if self.started:
            raise RuntimeError("Camera must be stopped before configuring")
        given = "preview" if camera_config is None else camera_config
        config = self._resolve(given)
        self._cam.apply(Controls(self, config.get("controls") or {}).make_dict())
        self.camera_config = config
        self.allocator.allocate(config)
        if isinstance(given, str) and given in ("preview", "still", "video"):
            getattr(self, f"{given}_configuration").update(config)
        elif isinstance(given, dict):  # as picamera2 does: the caller's dict gets what configure worked out
            for name in ("main", "lores", "raw"):
                if isinstance(given.get(name), dict) and config.get(name) is not None:
                    given[name].update({k: config[name][k] for k in ("format", "size", "stride", "framesize")
                                        if k in config[name]})
        self.encode_stream_name = config.get("encode") or "main"
        # As picamera2's: the configuration's controls, readable (picam2.controls.ExposureTime) and applied
        # (again: the same values) with the first frame.
        self.controls = Controls(self, config.get("controls") or {})

    def start(self, config: Any = None, show_preview: Any = False) -> None:
        """Start streaming (configuring first with ``config``, or 'preview' when never configured)."""
        if config is not None or not self.camera_config:
            self.configure(config)
        if show_preview:
            self.start_preview(show_preview)
        if self.started:
            return
        c = self.camera_config
        self._queue = RequestQueue(int(c["buffer_count"]), 1 if c["queue"] and c["buffer_count"] > 1 else 0)
        self._engine = Engine(self._cam, self._queue, self.controls.take, self._complete)
        self._engine.start()
        with self._state:
            self.started = True
            self._state.notify_all()

    def stop(self) -> None:
        """Stop streaming (harmless when stopped)."""
        if not self.started:
            return
        self.started = False
        engine, self._engine = self._engine, None
        engine.stop()

    def close(self) -> None:
        """Stop and release the camera (harmless twice)."""
        atexit.unregister(self.close)
        if not getattr(self, "is_open", False):
            return
        try:
            self.stop()
        finally:
            with self._state:
                self.is_open = False
                self._state.notify_all()
            with OPEN_LOCK:
                if OPEN.get(self.camera_idx) is self:
                    del OPEN[self.camera_idx]

    def set_controls(self, controls: Any) -> None:
        """Set controls; they apply together from the next frame that starts exposing."""
        self.controls.set_controls(controls)

    def start_preview(self, preview: Any = None, **kwargs: Any) -> None:
        """No window is shown: every preview runs as the NULL preview."""
        if preview not in (None, False, Preview.NULL):
            _log.warning("rollcam's picamera2 stand-in shows no preview window; running without one")

    def stop_preview(self) -> None:
        """Nothing to stop (no preview window)."""

    def set_overlay(self, overlay: Any) -> None:
        """An overlay for the preview: None, or a 4-channel (RGBA) array, checked as picamera2 does and kept
        in ``overlay``; with no preview window it is drawn nowhere."""
        if overlay is not None and (getattr(overlay, "ndim", 0) != 3 or overlay.shape[2] != 4):
            raise RuntimeError("Overlay must be a 4-channel image")
        self.overlay = overlay

    @property
    def stream_map(self) -> dict[str, Any]:
        """Each configured stream as libcamera describes it: ``stream_map["main"].configuration.size``,
        ``.stride``, ``.pixel_format``."""
        out = {}
        for name in ("main", "lores", "raw"):
            c = self.camera_config.get(name) if self.camera_config else None
            if c is not None:
                conf = SimpleNamespace(size=libcamera.Size(*c["size"]), stride=c.get("stride"),
                                       pixel_format=str(c["format"]), frame_size=c.get("framesize"))
                out[name] = SimpleNamespace(name=name, configuration=conf)
        return out

    # ------------------------------------------------------------------------------------ frames
    def _complete(self, plan: Any, frame: Any) -> CompletedRequest | None:
        """A completed request of a rendered frame: every stream's array and the metadata."""
        cam, c = self._cam, self.camera_config
        spec = cam.device.spec
        limits = cam.crop_limits()
        crop = cam.scaler_crop
        if crop is None:
            crop = aspect_crop(limits, c["main"]["size"]) if c["main"].get("preserve_ar", True) else limits
        rect = crop_pixels(crop, limits, spec.size)
        streams = {n: (None if n == "raw" else (c[n]["format"], c[n]["size"], rect))
                   for n in ("main", "lores", "raw") if c.get(n) is not None}
        pipeline = cam.device.imager.camera(spec).pipeline

        def picture() -> Any:
            return isp_picture(frame, pipeline.isp, spec.sensor.bit_depth, spec.bayer_order,
                               cam.extra.get("ColourGains"))
        arrays = stream_arrays(frame, streams, picture)
        queue = self._queue
        req = CompletedRequest(arrays, cam.metadata(frame, spec, crop), c, self, lambda r: queue.returned())
        for hook in (self.pre_callback, self.post_callback):
            if hook is not None:
                hook(req)
        self._encode(req)
        return req
