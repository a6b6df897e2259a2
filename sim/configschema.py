"""Table-driven validation of frozen config classes read from YAML (the sensor descriptions and their sections).

Each field of a config class carries its schema row (type, expected form, value check, default; ``spec`` makes
the field, ``schema(cls)`` gathers the rows) and each class a ``_rules`` table of checks that relate several
values. ``parse_section`` turns a YAML mapping into an object, rejecting unknown and missing keys; each class's
``__post_init__`` (``Checked``) runs its schema and rules, so objects made with ``dataclasses.replace`` are
checked too. Errors are ``InvalidKey`` (a ``ConfigError``) naming the dotted key, the expected form and the value.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import math
import reprlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

from rollcam.common.errors import ConfigError

_REQUIRED = object()
_short = reprlib.Repr()  # values in messages: a few items and levels, never a whole (aliased) structure
_short.maxstring = _short.maxother = 60
_short.maxlevel, _short.maxlist, _short.maxtuple, _short.maxdict = 3, 4, 4, 4


class InvalidKey(ConfigError):
    """A ConfigError about one dotted key, so outer levels can prefix their own key and the file."""

    def __init__(self, key: str, detail: str) -> None:
        super().__init__(f"{key}: {detail}")
        self.key, self.detail = key, detail


@dataclass(frozen=True)
class ListOf:
    item: Any


class SpecRow(NamedTuple):
    """One schema row: type (a Python type, ListOf, or a config class), expected form, check, default."""

    kind: Any
    form: str
    check: Callable[[Any], Any] | None = None
    default: Any = _REQUIRED


class Rule(NamedTuple):
    """A check relating several values. ``key`` may hold ``[]`` (``modes[].crop``): checked per item.

    ``ok``, ``form`` and ``shown`` take (obj, item, index); item is obj itself for keys without ``[]``.
    """

    key: str
    ok: Callable[[Any, Any, int], Any]
    form: Callable[[Any, Any, int], str]
    shown: Callable[[Any, Any, int], Any] | None = None


def positive(v: float) -> bool: return v > 0
def nonnegative(v: float) -> bool: return v >= 0
def nonempty(v: str | tuple) -> bool: return len(v) > 0


def one_of(*choices: Any) -> Callable[[Any], bool]:
    return lambda v: v in choices


def _is(kind: Any, v: Any) -> bool:
    if kind is float:
        return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
    if kind is int:
        return isinstance(v, int) and not isinstance(v, bool)
    if isinstance(kind, ListOf):
        return isinstance(v, tuple) and all(_is(kind.item, x) for x in v)
    return isinstance(v, kind)


def dotted(obj: Any, key: str) -> Any:
    return functools.reduce(getattr, key.split("."), obj) if key else obj


@functools.cache
def schema(cls: type) -> dict[str, SpecRow]:
    """The schema of a config class: key -> SpecRow, read from its fields' metadata."""
    return {f.name: f.metadata["spec"] for f in dataclasses.fields(cls)}


class Checked:
    """Mixin for the frozen config classes: check the ``schema`` rows, then the ``_rules``, after init."""

    _rules: ClassVar[tuple[Rule, ...]] = ()

    def __post_init__(self) -> None:
        for key, row in schema(type(self)).items():
            value = getattr(self, key)
            if value is None and row.default is None:
                continue
            if not _is(row.kind, value) or (row.check is not None and not row.check(value)):
                raise InvalidKey(key, f"expected {row.form}, got {_short.repr(value)}")
            if row.kind is float:
                object.__setattr__(self, key, float(value))
        for rule in self._rules:
            field, each, sub = rule.key.partition("[]")
            items = enumerate(getattr(self, field)) if each else [(0, self)]
            for i, item in items:
                if not rule.ok(self, item, i):
                    key = f"{field}[{i}]{sub}" if each else rule.key
                    path = sub.lstrip(".") if each else rule.key
                    shown = rule.shown(self, item, i) if rule.shown else dotted(item, path)
                    raise InvalidKey(key, f"expected {rule.form(self, item, i)}, got {_short.repr(shown)}")


def spec(kind: Any, form: str, check: Callable[[Any], Any] | None = None, default: Any = _REQUIRED) -> Any:
    """A dataclass field carrying its schema row (a ``SpecRow``); ``default`` makes the key optional.

    It returns a ``dataclasses.Field``, not a shared default; ruff's RUF009 cannot tell, hence its noqa marks.
    """
    spec = {"spec": SpecRow(kind, form, check, default)}
    if default is _REQUIRED:
        return dataclasses.field(metadata=spec)
    return dataclasses.field(default=default, metadata=spec)


def _parse(kind: Any, raw: Any, key: str) -> Any:
    """Turn raw YAML data into what ``kind`` describes; scalars pass through for the class to check."""
    if isinstance(kind, ListOf):
        if not isinstance(raw, list):
            raise InvalidKey(key, f"expected a list, got {_short.repr(raw)}")
        return tuple(_parse(kind.item, x, f"{key}[{i}]") for i, x in enumerate(raw))
    if isinstance(kind, type) and issubclass(kind, Checked):
        return parse_section(kind, raw, key)
    return raw


def parse_section(cls: type[Checked], raw: Any, key: str) -> Any:
    """Build one config object from a mapping: unknown and missing keys here, values in the class."""
    join = (lambda k: f"{key}.{k}") if key else str
    if not isinstance(raw, dict):
        raise InvalidKey(key or "top level", f"expected a mapping of keys to values, got {_short.repr(raw)}")
    rows = schema(cls)
    for name in raw:
        if name not in rows:
            near = difflib.get_close_matches(str(name), rows, n=1)
            hint = f"did you mean {near[0]!r}? " if near else ""
            raise InvalidKey(join(name), f"unknown key (value {_short.repr(raw[name])}); {hint}"
                             f"expected one of {list(rows)}")
    kwargs = {}
    for name, row in rows.items():
        if name in raw:
            kwargs[name] = _parse(row.kind, raw[name], join(name))
        elif row.default is _REQUIRED:
            raise InvalidKey(join(name), f"missing required key; expected {row.form}")
    try:
        return cls(**kwargs)
    except InvalidKey as e:
        raise InvalidKey(join(e.key), e.detail) from None
