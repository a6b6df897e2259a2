"""Table-driven validation of frozen config classes read from YAML (the sensor descriptions and their sections).

Each field of a config class carries its schema row (type, expected form, value check, default; ``_f`` makes
the field, ``_schema(cls)`` gathers the rows) and each class a ``_rules`` table of checks that relate several
values. ``_parse_section`` turns a YAML mapping into an object, rejecting unknown and missing keys; each class's
``__post_init__`` (``_Checked``) runs its schema and rules, so objects made with ``dataclasses.replace`` are
checked too. Errors are ``_Invalid`` (a ``ConfigError``) naming the dotted key, the expected form and the value.
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


class _Invalid(ConfigError):
    """A ConfigError about one dotted key, so outer levels can prefix their own key and the file."""

    def __init__(self, key: str, detail: str) -> None:
        super().__init__(f"{key}: {detail}")
        self.key, self.detail = key, detail


@dataclass(frozen=True)
class _ListOf:
    item: Any


class _Spec(NamedTuple):
    """One schema row: type (a Python type, _ListOf, or a config class), expected form, check, default."""

    kind: Any
    form: str
    check: Callable[[Any], Any] | None = None
    default: Any = _REQUIRED


class _Rule(NamedTuple):
    """A check relating several values. ``key`` may hold ``[]`` (``modes[].crop``): checked per item.

    ``ok``, ``form`` and ``shown`` take (obj, item, index); item is obj itself for keys without ``[]``.
    """

    key: str
    ok: Callable[[Any, Any, int], Any]
    form: Callable[[Any, Any, int], str]
    shown: Callable[[Any, Any, int], Any] | None = None


def _pos(v: float) -> bool: return v > 0
def _nonneg(v: float) -> bool: return v >= 0
def _nonempty(v: str | tuple) -> bool: return len(v) > 0


def _one_of(*choices: Any) -> Callable[[Any], bool]:
    return lambda v: v in choices


def _is(kind: Any, v: Any) -> bool:
    if kind is float:
        return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
    if kind is int:
        return isinstance(v, int) and not isinstance(v, bool)
    if isinstance(kind, _ListOf):
        return isinstance(v, tuple) and all(_is(kind.item, x) for x in v)
    return isinstance(v, kind)


def _dotted(obj: Any, key: str) -> Any:
    return functools.reduce(getattr, key.split("."), obj) if key else obj


@functools.cache
def _schema(cls: type) -> dict[str, _Spec]:
    """The schema of a config class: key -> _Spec, read from its fields' metadata."""
    return {f.name: f.metadata["spec"] for f in dataclasses.fields(cls)}


class _Checked:
    """Mixin for the frozen config classes: check the ``_schema`` rows, then the ``_rules``, after init."""

    _rules: ClassVar[tuple[_Rule, ...]] = ()

    def __post_init__(self) -> None:
        for key, spec in _schema(type(self)).items():
            value = getattr(self, key)
            if value is None and spec.default is None:
                continue
            if not _is(spec.kind, value) or (spec.check is not None and not spec.check(value)):
                raise _Invalid(key, f"expected {spec.form}, got {_short.repr(value)}")
            if spec.kind is float:
                object.__setattr__(self, key, float(value))
        for rule in self._rules:
            field, each, sub = rule.key.partition("[]")
            items = enumerate(getattr(self, field)) if each else [(0, self)]
            for i, item in items:
                if not rule.ok(self, item, i):
                    key = f"{field}[{i}]{sub}" if each else rule.key
                    path = sub.lstrip(".") if each else rule.key
                    shown = rule.shown(self, item, i) if rule.shown else _dotted(item, path)
                    raise _Invalid(key, f"expected {rule.form(self, item, i)}, got {_short.repr(shown)}")


def _f(kind: Any, form: str, check: Callable[[Any], Any] | None = None, default: Any = _REQUIRED) -> Any:
    """A dataclass field carrying its schema row; ``default`` makes the key optional.

    It returns a ``dataclasses.Field``, not a shared default; ruff's RUF009 cannot tell, hence its noqa marks.
    """
    spec = {"spec": _Spec(kind, form, check, default)}
    if default is _REQUIRED:
        return dataclasses.field(metadata=spec)
    return dataclasses.field(default=default, metadata=spec)


def _parse(kind: Any, raw: Any, key: str) -> Any:
    """Turn raw YAML data into what ``kind`` describes; scalars pass through for the class to check."""
    if isinstance(kind, _ListOf):
        if not isinstance(raw, list):
            raise _Invalid(key, f"expected a list, got {_short.repr(raw)}")
        return tuple(_parse(kind.item, x, f"{key}[{i}]") for i, x in enumerate(raw))
    if isinstance(kind, type) and issubclass(kind, _Checked):
        return _parse_section(kind, raw, key)
    return raw


def _parse_section(cls: type[_Checked], raw: Any, key: str) -> Any:
    """Build one config object from a mapping: unknown and missing keys here, values in the class."""
    join = (lambda k: f"{key}.{k}") if key else str
    if not isinstance(raw, dict):
        raise _Invalid(key or "top level", f"expected a mapping of keys to values, got {_short.repr(raw)}")
    schema = _schema(cls)
    for name in raw:
        if name not in schema:
            near = difflib.get_close_matches(str(name), schema, n=1)
            hint = f"did you mean {near[0]!r}? " if near else ""
            raise _Invalid(join(name), f"unknown key (value {_short.repr(raw[name])}); {hint}"
                           f"expected one of {list(schema)}")
    kwargs = {}
    for name, spec in schema.items():
        if name in raw:
            kwargs[name] = _parse(spec.kind, raw[name], join(name))
        elif spec.default is _REQUIRED:
            raise _Invalid(join(name), f"missing required key; expected {spec.form}")
    try:
        return cls(**kwargs)
    except _Invalid as e:
        raise _Invalid(join(e.key), e.detail) from None
