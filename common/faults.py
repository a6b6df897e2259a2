"""One fault description for every transport of the emulated camera, after vivid's error-injection controls.

A ``FaultPlan`` is parsed once from text (``rollcam emulate --faults``, the ``faults=`` option of an ``emu:``
URI, a fixture argument), validated, and frozen: ``drop=2%,error=1%,stall=0.5%,disconnect=300,seed=7``. Every
decision is a pure function of the seed, the fault kind and the index of the event it is asked about (frame
``n``, payload ``k``, reply byte ``b``, the ``k``-th QBUF), so a run with the same plan and the same events
injects the same faults whatever the timing. Each transport applies the kinds it has a failure for to its own
unit (docs/faults.md has the table) and counts what it injected in a ``FaultStats`` through its own
``FaultInjector``, so a test compares the failures a client saw with the injected counts.

Keys (rates are percentages, the ``%`` sign optional; a key without ``=value`` takes its default):

- ``seed=N``: the plan's seed (default 0).
- rates: ``drop`` (frames or bytes lost), ``error`` (frames flagged bad), ``corrupt`` (bytes garbled),
  ``delay`` (replies / parts held for ``delay_ms``, default 500), ``stall`` (USB STALL handshake),
  ``babble`` (USB overflow), ``short`` (USB short packets), ``cut`` (HTTP connection cut mid-part).
- ``disconnect=N``: the device goes away after N frames delivered.
- one-shot request errors, vivid's REQBUFS/QBUF/STREAMON and more: ``qbuf=EIO@3`` fails the 3rd QBUF with EIO
  (``qbuf`` alone: the first, with EINVAL, as vivid's buttons do).
- ``seqwrap[=N]``: sequence numbers start N frames before the 32-bit wrap (default 128: vivid's 0xffffff80).
- ``tswrap[=S]``: timestamps start S seconds before the signed 64-bit nanosecond wrap (default 16, as vivid),
  counted from the stream's start.
"""

from __future__ import annotations

import errno
import zlib
from dataclasses import dataclass, field, fields
from typing import Any

from .errors import ConfigError
from .lifecycle import Stats

RATES = ("drop", "error", "corrupt", "delay", "stall", "babble", "short", "cut")
"""Fault kinds given as a percentage of the events they apply to."""
REQUESTS = ("reqbufs", "querybuf", "qbuf", "dqbuf", "streamon", "streamoff", "s_fmt", "s_parm", "s_ctrl")
"""Requests (V4L2 ioctls, lower case without ``VIDIOC_``) that a one-shot error can be injected into."""
DEFAULT_DELAY_MS = 500
DEFAULT_SEQWRAP = 128  # vivid starts the sequence at 0xffffff80
DEFAULT_TSWRAP_S = 16  # vivid: (1 << 63) - 16 s
U32 = 1 << 32
S64 = 1 << 63
MAX_DELAY_MS = 60_000
_M64 = (1 << 64) - 1


def _mix64(x: int) -> int:
    """splitmix64's finaliser: a bijective scramble of a 64-bit word."""
    x = (x + 0x9E3779B97F4A7C15) & _M64
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & _M64
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & _M64
    return x ^ (x >> 31)


def draw(seed: int, kind: str, index: int) -> int:
    """The 64-bit draw for event ``index`` of fault ``kind`` under ``seed``: a pure function, no state."""
    salt = zlib.crc32(kind.encode())
    return _mix64(_mix64((seed & _M64) ^ (salt << 32)) ^ (index & _M64))


@dataclass(frozen=True)
class RequestFault:
    """A one-shot error: the ``nth`` call (1-based) of ``request`` fails with ``err``."""

    request: str
    err: int
    nth: int = 1

    def to_text(self) -> str:
        return f"{self.request}={errno.errorcode.get(self.err, self.err)}@{self.nth}"


@dataclass(frozen=True)
class FaultPlan:
    """A validated, immutable fault description (see the module docstring for the keys); ``FaultPlan()`` is no
    fault at all. Build one with ``parse`` (text) or ``of`` (text, a plan or None)."""

    seed: int = 0
    rates: tuple[tuple[str, float], ...] = ()  # (kind, percent) for the rates given, in RATES order
    delay_ms: int = DEFAULT_DELAY_MS
    disconnect: int | None = None
    requests: tuple[RequestFault, ...] = ()
    seqwrap: int | None = None
    tswrap_s: int | None = None

    def __post_init__(self) -> None:
        for kind, pct in self.rates:
            if kind not in RATES or not 0.0 <= pct <= 100.0:
                raise ConfigError(f"fault rate {kind}={pct!r}: expected one of {RATES} at 0..100 %")

    # ------------------------------------------------------------------------------------------ text
    @classmethod
    def parse(cls, text: str, owner: str = "faults") -> FaultPlan:
        """A plan from ``key=value,key,...`` text; a bad key or value raises ConfigError naming it."""
        if not isinstance(text, str):
            raise ConfigError(f"{owner}: expected fault text like 'drop=2%,seed=7', got {text!r}")
        seen: dict[str, str | None] = {}
        for item in text.split(","):
            item = item.strip()
            if not item:
                continue
            key, sep, value = item.partition("=")
            key = key.strip().lower()
            if key in seen:
                raise ConfigError(f"{owner}: fault {key!r} given twice in {text!r}")
            seen[key] = value.strip() if sep else None
        kw: dict[str, Any] = {}
        rates: dict[str, float] = {}
        requests: list[RequestFault] = []
        key, value = "", None
        try:
            for key, value in seen.items():
                _take(key, value, kw, rates, requests)
        except ValueError as exc:
            shown = key if value is None else f"{key}={value}"
            raise ConfigError(f"{owner}: fault {shown!r} in {text!r}: {exc}") from None
        return cls(rates=tuple((k, rates[k]) for k in RATES if k in rates), requests=tuple(requests), **kw)

    @classmethod
    def of(cls, value: FaultPlan | str | None, owner: str = "faults") -> FaultPlan:
        """``value`` as a plan: a plan as it is, text parsed, None as no fault."""
        if value is None:
            return cls()
        if isinstance(value, FaultPlan):
            return value
        return cls.parse(value, owner)

    def to_text(self) -> str:
        """The canonical text (``parse(plan.to_text()) == plan``)."""
        items = [f"{k}={_num(p)}%" for k, p in self.rates]
        if self.delay_ms != DEFAULT_DELAY_MS:
            items.append(f"delay_ms={self.delay_ms}")
        if self.disconnect is not None:
            items.append(f"disconnect={self.disconnect}")
        items += [r.to_text() for r in self.requests]
        if self.seqwrap is not None:
            items.append(f"seqwrap={self.seqwrap}")
        if self.tswrap_s is not None:
            items.append(f"tswrap={self.tswrap_s}")
        if items and self.seed:
            items.append(f"seed={self.seed}")
        return ",".join(items)

    def __str__(self) -> str:
        return self.to_text() or "none"

    def __bool__(self) -> bool:
        """True when the plan injects anything."""
        return bool(self.rates or self.disconnect is not None or self.requests or self.seqwrap or self.tswrap_s)

    # ------------------------------------------------------------------------------------------ decisions
    def rate(self, kind: str) -> float:
        """The percentage given for ``kind`` (0 when not given)."""
        return next((p for k, p in self.rates if k == kind), 0.0)

    def fires(self, kind: str, index: int, events: str = "") -> bool:
        """Whether fault ``kind`` hits event ``index``: a pure function of (seed, kind, index). ``events`` names
        a second series of events the same kind applies to (a USB camera's control requests beside its
        payloads), drawn independently."""
        pct = self.rate(kind)
        return pct > 0 and draw(self.seed, f"{kind}/{events}" if events else kind, index) < pct / 100.0 * 2.0**64

    def pick(self, kind: str, index: int, n: int) -> int:
        """A reproducible choice in ``0..n-1`` for event ``index`` of ``kind`` (where to cut, which bit to flip)."""
        return draw(self.seed, kind + ".pick", index) % max(n, 1)

    def request_error(self, request: str, nth: int) -> int | None:
        """The errno the ``nth`` call (1-based) of ``request`` fails with, or None."""
        return next((r.err for r in self.requests if r.request == request and r.nth == nth), None)

    def sequence(self, n: int) -> int:
        """Frame sequence number ``n`` (from 0) as a 32-bit field carries it, shifted toward the wrap by
        ``seqwrap``."""
        return (n + (U32 - self.seqwrap if self.seqwrap else 0)) % U32

    def timestamp_ns(self, t_ns: int, start_ns: int = 0) -> int:
        """Timestamp ``t_ns`` shifted so that ``start_ns`` (the stream's start, as vivid offsets from
        STREAMON) lies ``tswrap_s`` seconds before the signed 64-bit ns wrap, and wrapped as an int64 is (past
        the wrap it is negative, as the kernel's ktime_t would be)."""
        if not self.tswrap_s:
            return t_ns
        t = t_ns - start_ns + S64 - self.tswrap_s * 1_000_000_000
        return (t + S64) % (2 * S64) - S64


@dataclass
class FaultStats(Stats):
    """Faults one transport injected, by kind (``FaultInjector`` counts them as they fire)."""

    dropped: int = 0
    errors: int = 0
    corrupted: int = 0
    delayed: int = 0
    stalls: int = 0
    babbles: int = 0
    shorts: int = 0
    cuts: int = 0
    disconnects: int = 0
    request_errors: int = 0
    damaged_frames: int = 0  # frames that reached the client incomplete because of payload faults


_COUNTER = {"drop": "dropped", "error": "errors", "corrupt": "corrupted", "delay": "delayed", "stall": "stalls",
            "babble": "babbles", "short": "shorts", "cut": "cuts"}


@dataclass
class FaultInjector:
    """One transport's use of a plan: the decisions, counted in ``stats`` as they fire, and per-request call
    counts for the one-shot errors. Not thread-safe: a transport asks from the thread that owns the events."""

    plan: FaultPlan = field(default_factory=FaultPlan)
    stats: FaultStats = field(default_factory=FaultStats)

    def __post_init__(self) -> None:
        self._calls: dict[str, int] = {}

    def __bool__(self) -> bool:
        return bool(self.plan)

    def hit(self, kind: str, index: int, events: str = "") -> bool:
        """``plan.fires(kind, index, events)``, counted when True."""
        if not self.plan.fires(kind, index, events):
            return False
        counter = _COUNTER[kind]
        setattr(self.stats, counter, getattr(self.stats, counter) + 1)
        return True

    def request(self, name: str) -> int | None:
        """Count one call of request ``name``; the errno it must fail with, or None."""
        if not self.plan.requests:
            return None
        n = self._calls[name] = self._calls.get(name, 0) + 1
        err = self.plan.request_error(name, n)
        self.stats.request_errors += err is not None
        return err

    def disconnect_due(self, delivered: int) -> bool:
        """Whether the device goes away now, with ``delivered`` frames delivered (counted once)."""
        if self.plan.disconnect is None or self.stats.disconnects or delivered < self.plan.disconnect:
            return False
        self.stats.disconnects += 1
        return True


def _take(key: str, value: str | None, kw: dict[str, Any], rates: dict[str, float],
          requests: list[RequestFault]) -> None:
    """Parse one ``key[=value]`` of a plan into the constructor's arguments (ValueError saying why not)."""
    if key in RATES:
        rates[key] = _percent(_needs(value))
    elif key == "seed":
        kw["seed"] = _int(_needs(value), 0, _M64)
    elif key == "delay_ms":
        kw["delay_ms"] = _int(_needs(value), 0, MAX_DELAY_MS)
    elif key == "disconnect":
        kw["disconnect"] = _int(_needs(value), 0, U32)
    elif key == "seqwrap":
        kw["seqwrap"] = DEFAULT_SEQWRAP if value is None else _int(value, 1, U32 - 1)
    elif key == "tswrap":
        kw["tswrap_s"] = DEFAULT_TSWRAP_S if value is None else _int(value, 1, 1 << 32)
    elif key in REQUESTS:
        requests.append(_request(key, value))
    else:
        raise ValueError(f"unknown fault; known: {', '.join(_known())}")


def _needs(value: str | None) -> str:
    if value is None or value == "":
        raise ValueError("needs a value")
    return value


def _percent(text: str) -> float:
    t = text.removesuffix("%").strip()
    try:
        value = float(t)
    except ValueError:
        raise ValueError("expected a percentage like 2% or 0.5") from None
    if not 0.0 <= value <= 100.0:  # also refuses nan
        raise ValueError("a percentage must be in 0..100")
    return value


def _int(text: str, lo: int, hi: int) -> int:
    try:
        value = int(text, 10)
    except ValueError:
        raise ValueError(f"expected a whole number in {lo}..{hi}") from None
    if not lo <= value <= hi:
        raise ValueError(f"expected a whole number in {lo}..{hi}")
    return value


def _request(key: str, value: str | None) -> RequestFault:
    name, _, nth = (value or "").partition("@")
    name = name.strip().upper() or "EINVAL"
    if name.isdigit():
        err = int(name)
        if err not in errno.errorcode:
            raise ValueError(f"{err} is not an errno")
    else:
        err = getattr(errno, name, None)
        if not isinstance(err, int) or not name.startswith("E"):
            raise ValueError(f"{name!r} is not an errno name (EINVAL, ENOMEM, EIO, ...)")
    return RequestFault(key, err, _int(nth, 1, U32) if nth else 1)


def _num(x: float) -> str:
    return f"{x:g}"


def _known() -> list[str]:
    return ["seed", *RATES, "delay_ms", "disconnect", *REQUESTS, "seqwrap", "tswrap"]


FAULT_COUNTERS = tuple(f.name for f in fields(FaultStats))
"""The names of the ``FaultStats`` counters (for status pages and docs)."""
