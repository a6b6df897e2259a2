"""Configuration objects: picamera2's configuration dictionaries as objects with checked attributes.

``Picamera2.preview_configuration`` (and ``still_``, ``video_``) are ``CameraConfiguration`` objects; a field
that does not exist is a RuntimeError (a typo caught), a dict set on a stream field becomes a
``StreamConfiguration``, and ``size``/``format`` on the camera configuration mean the main stream's.
"""

from __future__ import annotations

from typing import Any, ClassVar


class Configuration:
    """Base: only ``FIELDS`` may be set; ``NESTED`` fields turn dicts into their class; ``FORWARD`` fields are
    another field's."""

    FIELDS: ClassVar[tuple[str, ...]] = ()
    NESTED: ClassVar[dict[str, type[Configuration]]] = {}
    FORWARD: ClassVar[dict[str, str]] = {}

    def __init__(self, d: dict[str, Any] | Configuration | None = None) -> None:
        if isinstance(d, Configuration):
            d = d.make_dict()
        for name in self.FIELDS:
            object.__setattr__(self, name, None)
        for k, v in (d or {}).items():
            setattr(self, k, v)

    def __setattr__(self, name: str, value: Any) -> None:
        if name in self.FORWARD:
            setattr(getattr(self, self.FORWARD[name]), name, value)
            return
        if name not in self.FIELDS:
            raise RuntimeError(f"Invalid field {name!r}")
        if name in self.NESTED and isinstance(value, dict):
            value = self.NESTED[name](value)
        object.__setattr__(self, name, value)

    def __getattribute__(self, name: str) -> Any:
        forward = type(self).FORWARD
        if name in forward:
            return getattr(object.__getattribute__(self, forward[name]), name)
        return object.__getattribute__(self, name)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.make_dict()!r})"

    def update(self, update_dict: dict[str, Any]) -> None:
        """Set several fields."""
        for k, v in update_dict.items():
            setattr(self, k, v)

    def make_dict(self) -> dict[str, Any]:
        """The configuration as picamera2's dictionary (nested configurations as dicts)."""
        out = {}
        for name in self.FIELDS:
            value = getattr(self, name)
            if isinstance(value, Configuration):
                value = value.make_dict()
            out[name] = value
        return out

    def align(self, optimal: bool = True) -> None:
        """Round the size down as the ISP wants it: widths to 32 pixels (16 for 32-bit RGB, 64 for YUV420)
        when ``optimal``, else to even numbers."""
        align = 2
        if optimal:
            align = {"YUV420": 64, "YVU420": 64, "XBGR8888": 16, "XRGB8888": 16}.get(self.format, 32)
        w, h = self.size
        self.size = (w - w % align, h - h % 2)


class StreamConfiguration(Configuration):
    """One stream: size, format, stride, framesize, preserve_ar."""

    FIELDS = ("size", "format", "stride", "framesize", "preserve_ar")


class SensorConfiguration(Configuration):
    """The sensor mode asked for: output_size, bit_depth."""

    FIELDS = ("output_size", "bit_depth")


class CameraConfiguration(Configuration):
    """A whole camera configuration: streams (main, lores, raw), sensor, controls, buffers, transform."""

    FIELDS = ("use_case", "buffer_count", "transform", "display", "encode", "colour_space", "controls", "main",
              "lores", "raw", "queue", "sensor")
    NESTED: ClassVar[dict[str, type[Configuration]]] = {
        "main": StreamConfiguration, "lores": StreamConfiguration, "raw": StreamConfiguration,
        "sensor": SensorConfiguration}
    FORWARD: ClassVar[dict[str, str]] = {"size": "main", "format": "main"}

    def __init__(self, d: dict[str, Any] | Configuration | None = None, picam2: Any = None) -> None:
        from .controls import Controls

        if isinstance(d, Configuration):
            d = d.make_dict()
        d = dict(d or {})
        if "controls" in d:
            d["controls"] = Controls(picam2, d["controls"])
        super().__init__(d)
        if "raw" not in d:
            self.enable_raw()
        if "sensor" not in d:
            self.sensor = SensorConfiguration()

    def make_dict(self) -> dict[str, Any]:
        out = super().make_dict()
        if hasattr(out.get("controls"), "make_dict"):
            out["controls"] = out["controls"].make_dict()
        return out

    def enable_lores(self, onoff: bool = True) -> None:
        """Add (or remove) a lores stream of the main stream's size, YUV420."""
        self.lores = StreamConfiguration({"size": self.main.size, "format": "YUV420"}) if onoff else None

    def enable_raw(self, onoff: bool = True) -> None:
        """Add (or remove) a raw stream; its size and format are filled in when the camera is configured."""
        self.raw = StreamConfiguration({"size": None, "format": None}) if onoff else None

    def align(self, optimal: bool = True) -> None:
        """Align main and lores (raw sizes are the sensor's)."""
        self.main.align(optimal)
        if self.lores is not None:
            self.lores.align(optimal)
