"""``key=value&...`` options of source URIs and detector specs: one query parser and one set of value parsers.

Sources (``emu:imx219?size=640x480``) and detectors (``hog?scale=1.1``) take options the same way; both parse
their query here and convert values with the parsers below, so a bad option reads the same everywhere.
"""

from __future__ import annotations

import math
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


def parse_size(text: str) -> tuple[int, int]:
    """Option parser: ``'1920x1080'`` -> (1920, 1080), both positive."""
    try:
        w, h = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise ConfigError(f"size {text!r} is not WIDTHxHEIGHT (e.g. 1920x1080)") from None
    if w <= 0 or h <= 0:
        raise ConfigError(f"size {text!r} must be positive")
    return w, h


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
