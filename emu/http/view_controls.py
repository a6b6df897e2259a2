"""The live view's controls: what the page may change on a device, and the one call that changes it.

A page control is a camera option of ``rollcam.firmware.options.OPTIONS`` (``exposure_us``, ``gain``, ``fps``,
``shutter``, ...) written as text to ``FirmwareCamera.set_options``, the call behind the serial ``OPT`` and
``SCENE`` commands; so the page, the serial line and the registers edit one spec, a change through any of them
shows in the others, and a bad value gets the option table's own message. Options a streaming device refuses
(shutter, readout, flips, format) are applied as a serial user would: stream off, set, stream on (the stream
is restarted even when the value is refused). ``ViewControls`` is what the page server needs from any control
set: ``describe()`` and ``apply(name, text)``; a host source without controls has ``NoControls``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from rollcam.common.errors import ConfigError
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.options import OPTIONS, SHUTTERS, as_text

READOUTS = ("top_to_bottom", "bottom_to_top", "left_to_right", "right_to_left")
EGO_PRESETS = ("none", "pan", "walk", "vehicle", "drone")  # rollcam.sim.scenegen.ego_preset's names
SPEEDS = ("static", "normal", "fast")  # rollcam.sim.scenegen.SPEED_PRESETS (or a multiplier)
MAX_VALUE_CHARS = 64  # a control value is a short text; longer is refused before any parser sees it


class ViewControls(Protocol):
    """What the live view needs from a device's controls."""

    def describe(self) -> dict[str, dict[str, Any]]:
        """Every control: ``label``, ``kind`` (number, choice, bool, text), ``value`` (text), ``choices``."""

    def apply(self, name: str, value: str) -> str:
        """Set control ``name`` from text; return the value in effect (text). ConfigError/DeviceError if refused."""

    def version(self) -> object:
        """An object that is replaced whenever any control changes (through any door); compared by identity."""


class NoControls:
    """A source the page cannot change (a file, a stream)."""

    def describe(self) -> dict[str, dict[str, Any]]:
        return {}

    def apply(self, name: str, value: str) -> str:
        raise ConfigError(f"this source has no controls (asked to set {name!r})")

    def version(self) -> object:
        return NoControls


@dataclass(frozen=True)
class PageControl:
    """One control of the page: the option it writes, how the page shows it, whether a stream must stop."""

    name: str
    label: str
    kind: str
    choices: Callable[[FirmwareCamera], list[str]] | None = None
    idle_only: bool = False
    unit: str = ""


def _fixed(*items: str) -> Callable[[FirmwareCamera], list[str]]:
    return lambda cam: list(items)


PAGE_CONTROLS: dict[str, PageControl] = {c.name: c for c in (
    PageControl("exposure_us", "exposure", "number", unit="us"),
    PageControl("gain", "gain", "number", unit="x"),
    PageControl("fps", "frame rate", "number", unit="fps"),
    PageControl("shutter", "shutter", "choice", _fixed(*SHUTTERS), idle_only=True),
    PageControl("readout", "readout", "choice", _fixed(*READOUTS), idle_only=True),
    PageControl("speed", "walking speed", "text", _fixed(*SPEEDS)),
    PageControl("ego", "ego-motion", "choice", _fixed(*EGO_PRESETS)),
    PageControl("test_pattern", "test pattern", "choice", lambda cam: list(cam.traits.test_pattern_codes)),
    PageControl("hflip", "mirror", "bool", idle_only=True),
    PageControl("vflip", "flip", "bool", idle_only=True),
    PageControl("format", "format", "choice", lambda cam: [f.strip() for f in cam.formats], idle_only=True),
    PageControl("physics", "sensor model", "bool"),
    PageControl("vignette", "vignetting", "number"),
    PageControl("lens_blur_px", "lens blur", "number", unit="px"),
    PageControl("defocus_px", "defocus", "number", unit="px"),
    PageControl("sharpen", "sharpening", "number"),
    PageControl("jpeg_quality", "JPEG quality", "number"),
)}
"""The page's controls, in the order it shows them (each is an option of ``OPTIONS``)."""


class CameraControls:
    """The page's controls over one ``FirmwareCamera``, through ``set_options`` (the serial ``OPT`` path)."""

    def __init__(self, camera: FirmwareCamera) -> None:
        self.camera = camera

    def _offered(self) -> list[PageControl]:
        scene = self.camera.spec.scene
        return [c for c in PAGE_CONTROLS.values() if OPTIONS[c.name].scenes is None or scene in OPTIONS[c.name].scenes]

    def version(self) -> object:
        """The camera's spec: every door replaces it whole on a change."""
        return self.camera.spec

    def describe(self) -> dict[str, dict[str, Any]]:
        values = self.camera.spec.option_values()
        return {c.name: {"label": c.label, "kind": c.kind, "unit": c.unit, "value": as_text(values[c.name]),
                         "choices": c.choices(self.camera) if c.choices else None, "idle_only": c.idle_only}
                for c in self._offered()}

    def apply(self, name: str, value: str) -> str:
        control = next((c for c in self._offered() if c.name == name), None)
        if control is None:
            raise ConfigError(f"no page control {name!r}; controls: {[c.name for c in self._offered()]}")
        if not isinstance(value, str) or len(value) > MAX_VALUE_CHARS:
            raise ConfigError(f"control {name!r} takes a text value of at most {MAX_VALUE_CHARS} characters, "
                              f"got {str(value)[:MAX_VALUE_CHARS + 8]!r}")
        cam = self.camera
        restart = control.idle_only and cam.streaming
        if restart:
            cam.stream_off()
        try:
            cam.set_options({name: value})
        finally:
            if restart:
                cam.stream_on()
        return as_text(cam.spec.option_values()[name])
