"""``key=value&...`` options and their values: one query parser and one set of value parsers.

Sources (``emu:imx219?size=640x480``), the ``#fragment`` of ``http://`` sources and detectors (``hog?scale=1.1``)
take options the same way; they parse their query here and convert values with the parsers below, and the CLI
turns the same parsers into argparse types (``rollcam.host.commands.value_type``), so a bad value reads the same
everywhere. A value parser takes the text and returns the value or raises ``ValueError`` saying what it must be.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Callable
from typing import Any
from urllib.parse import parse_qsl

from .errors import ConfigError, RollcamError


def parse_query(query: str, owner: str, error: type[RollcamError]) -> dict[str, str]:
    """``a=1&b=2`` -> {'a': '1', 'b': '2'}; empty or repeated option names raise ``error`` naming ``owner``."""
    options: dict[str, str] = {}
    for key, value in parse_qsl(query, keep_blank_values=True):
        if not key:
            raise error(f"{owner}: empty option name in query {query!r}")
        if key in options:
            raise error(f"{owner}: option {key!r} given twice")
        options[key] = value
    return options


def convert_option(options: dict[str, str], key: str, kind: Callable[[str], Any], default: Any, owner: str,
                   error: type[RollcamError]) -> Any:
    """Option ``key`` converted by ``kind``, or ``default`` when absent; a bad value raises ``error`` naming it."""
    if key not in options:
        return default
    raw = options[key]
    try:
        return kind(raw)
    except (TypeError, ValueError, ConfigError) as exc:
        raise error(f"{owner}: option {key}={raw!r} is invalid ({exc})") from None


def reject_unknown(options: dict[str, str], allowed: set[str], owner: str, error: type[RollcamError]) -> None:
    """Raise ``error`` naming the options not in ``allowed`` and the ones that are."""
    unknown = set(options) - allowed
    if unknown:
        raise error(f"{owner}: unknown option(s) {sorted(unknown)}; known: {sorted(allowed)}")


def finite_float(text: str) -> float:
    """Option parser: a finite float (``nan`` and ``inf`` are refused)."""
    value = float(text)
    if not math.isfinite(value):
        raise ValueError("must be a finite number")
    return value


def positive_float(text: str) -> float:
    """Option parser: a finite float above zero."""
    value = finite_float(text)
    if value <= 0:
        raise ValueError("must be greater than 0")
    return value


def non_negative_float(text: str) -> float:
    """Option parser: a finite float >= 0."""
    value = finite_float(text)
    if value < 0:
        raise ValueError("must be a number >= 0")
    return value


def positive_int(text: str) -> int:
    """Option parser: an integer >= 1."""
    value = int(text)
    if value < 1:
        raise ValueError("must be an integer >= 1")
    return value


def non_negative_int(text: str) -> int:
    """Option parser: an integer >= 0."""
    value = int(text)
    if value < 0:
        raise ValueError("must be an integer >= 0")
    return value


JPEG_QUALITY = 85
"""The one JPEG quality default (1..100) of every MJPEG encoder: HTTP (``emulate --quality``), UVC (wCompQuality
8500), V4L2 (``rollcam.sim.codecs`` re-exports it); here, beside its parser, because the CLI reads it numpy-free."""

SERIAL = "0001"
"""The one default serial number of an emulated sensor: it seeds the fixed-pattern noise (DSNU/PRNU) and names
the USB device (iSerialNumber), so a camera built any way (``emu:``, ``rollcam emulate``, a ``SyntheticCamera``
or ``SensorModel`` made directly) is the same sensor unless told otherwise."""


def jpeg_quality(value: str | int) -> int:
    """A JPEG quality, an integer in 1..100, from text (an option) or an integer (numpy's too); ConfigError
    naming the value otherwise."""
    try:
        quality = int(value, 10) if isinstance(value, str) else operator.index(value)
    except (TypeError, ValueError):
        quality = None
    if quality is None or isinstance(value, bool) or not 1 <= quality <= 100:
        raise ConfigError(f"JPEG quality {value!r} is not an integer in 1..100")
    return quality


TRUE_WORDS = ("1", "on", "true", "yes")
FALSE_WORDS = ("0", "off", "false", "no")


def parse_bool(text: str) -> bool:
    """Option parser: the one boolean vocabulary (1/on/true/yes, 0/off/false/no; any case)."""
    word = str(text).strip().lower()
    if word in TRUE_WORDS:
        return True
    if word in FALSE_WORDS:
        return False
    raise ValueError(f"expected one of {'/'.join(TRUE_WORDS)} or {'/'.join(FALSE_WORDS)}, got {text!r}")


def fraction(text: str) -> float:
    """Option parser: a number in [0, 1] (a share: visible fraction, overlap)."""
    value = finite_float(text)
    if not 0.0 <= value <= 1.0:
        raise ValueError("must be a number in [0, 1]")
    return value


def positive_fraction(text: str) -> float:
    """Option parser: a number in (0, 1] (an IoU threshold: 0 would match anything)."""
    value = finite_float(text)
    if not 0.0 < value <= 1.0:
        raise ValueError("must be a number in (0, 1]")
    return value


def name_list(text: str) -> tuple[str, ...]:
    """Option parser: ``a,b,c`` -> ('a', 'b', 'c'); blanks around names are dropped, an empty list refused."""
    items = tuple(t.strip() for t in text.split(",") if t.strip())
    if not items:
        raise ValueError("must be a comma-separated list of names")
    return items


def _pair(text: str, kind: Callable[[str], Any], what: str) -> tuple[Any, Any]:
    parts = text.lower().split("x")
    if len(parts) != 2:
        raise ConfigError(f"size {text!r} is not {what}")
    try:
        return kind(parts[0]), kind(parts[1])
    except ValueError:
        raise ConfigError(f"size {text!r} is not {what}") from None


def parse_size(text: str) -> tuple[int, int]:
    """Option parser: ``'1920x1080'`` -> (1920, 1080), both sides positive integers."""
    w, h = _pair(text, int, "WIDTHxHEIGHT (e.g. 1920x1080)")
    if w <= 0 or h <= 0:
        raise ConfigError(f"size {text!r} must be positive")
    return w, h


def box_size(text: str) -> tuple[float, float]:
    """Option parser: ``'6x16'`` -> (6.0, 16.0), a box's width and height in pixels, both >= 0."""
    w, h = _pair(text, finite_float, "WIDTHxHEIGHT in pixels (e.g. 6x16)")
    if w < 0 or h < 0:
        raise ConfigError(f"size {text!r} must not be negative")
    return w, h


def parse_host_port(text: str, default_host: str = "127.0.0.1") -> tuple[str, int]:
    """Option parser: ``HOST:PORT``, ``[IPv6]:PORT``, ``:PORT`` or ``PORT`` -> (host, port); host defaults to
    127.0.0.1."""
    host, sep, port = text.rpartition(":")
    host = host.strip("[]") if sep else ""
    try:
        number = int(port)
    except ValueError:
        raise ConfigError(f"expected HOST:PORT, got {text!r}") from None
    if not 0 <= number <= 65535:
        raise ConfigError(f"port {number} is not in 0..65535 (in {text!r})")
    return host or default_host, number


def usb_id(text: str) -> tuple[int, int]:
    """Option parser: ``'1209:0001'`` -> (0x1209, 0x0001), a USB vendor and product ID in hex."""
    try:
        vid, pid = (int(v, 16) for v in text.split(":"))
    except ValueError:
        raise ConfigError(f"{text!r} is not VID:PID in hex (e.g. 1209:0001)") from None
    if not (0 <= vid <= 0xFFFF and 0 <= pid <= 0xFFFF):
        raise ConfigError(f"VID:PID {text!r} is out of range (each 0000..ffff)")
    return vid, pid
