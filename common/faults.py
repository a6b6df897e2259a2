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

Lab faults, after what camera HIL rigs inject (docs/faults.md):

- frame-counter rates: ``seqrewrite`` (the counter jumps to ``seqrewrite_to``, default 0, and counts on from
  there), ``seqfreeze`` (the counter repeats the previous frame's), ``seqskip`` (the counter advances by
  ``seqskip_by`` more than 1, default 1);
- image rates: ``grey`` (a mid-grey frame), ``black`` (a black frame), ``frozen`` (the previous image again);
- ``regreset``: the share of frames at which the sensor's registers reset: its controls return to defaults;
- sensor defects, made by the sensor model (``rollcam.sim.defects``): ``stuck=N``, ``dead=N``, ``hot=N``
  pixels and ``soiling=N`` blobs, at seeded places; ``burst`` (rate): a run of ``burst_px`` (default 64)
  corrupted pixels on a frame; ``hot_dn_per_ms`` (default 40) how fast a hot pixel fills.

The AI Camera's own failures, in its in-sensor stage (``rollcam.firmware.insensor_stage``; a camera without an
in-sensor network has none of them):

- ``loaderfail=MS``: MS ms of device time after the stream starts, the IMX500's firmware loader fails ("failed
  to load loader firmware", raspberrypi/libcamera issue 355): no frame is made from then on;
- ``fetimeout`` (rate): the share of frames at which the front end stops ("Camera frontend has timed out!",
  raspberrypi/rpicam-apps issue 927); the first hit ends the stream;
- ``dnn_us=N``: each inference takes N us whatever the network's MACs (a network slower than the frame rate:
  Ultralytics measure YOLO11n at 58.8 ms a frame on the AI Camera); the frames it has no time for are skipped.
"""

from __future__ import annotations

import errno
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Any

from .errors import ConfigError
from .lifecycle import Stats
from .mixing import MASK64, splitmix64
from .values import bounded

COUNTER_FAULTS = ("seqrewrite", "seqfreeze", "seqskip")
"""Frame-counter faults, in the order they take precedence when several hit one frame."""
IMAGE_FAULTS = ("grey", "black", "frozen")
"""Faults that replace a frame's image, in the order they take precedence."""
RATES = ("drop", "error", "corrupt", "delay", "stall", "babble", "short", "cut", *COUNTER_FAULTS, *IMAGE_FAULTS,
         "regreset", "burst", "fetimeout")
"""Fault kinds given as a percentage of the events they apply to."""
DEFECTS = ("stuck", "dead", "hot", "soiling")
"""Sensor defects given as a count (of pixels; of blobs for ``soiling``) placed by the seed."""
MAX_DEFECTS = 1 << 20
REQUESTS = ("reqbufs", "querybuf", "qbuf", "dqbuf", "streamon", "streamoff", "s_fmt", "s_parm", "s_ctrl")
"""Requests (V4L2 ioctls, lower case without ``VIDIOC_``) that a one-shot error can be injected into."""
DEFAULT_DELAY_MS = 500
DEFAULT_SEQWRAP = 128  # vivid starts the sequence at 0xffffff80
DEFAULT_TSWRAP_S = 16  # vivid: (1 << 63) - 16 s
U32 = 1 << 32
S64 = 1 << 63
MAX_DELAY_MS = 60_000
DEFAULT_BURST_PX = 64
DEFAULT_HOT_DN_PER_MS = 40
MAX_LOADERFAIL_MS = 1 << 40
MAX_DNN_US = 60_000_000
INSENSOR_FAULTS = ("loaderfail", "fetimeout", "dnn_us")
"""The AI Camera's faults, applied by its in-sensor stage."""
PARAMS = {"delay_ms": (DEFAULT_DELAY_MS, 0, MAX_DELAY_MS), "seqrewrite_to": (0, 0, U32 - 1),
          "seqskip_by": (1, 1, U32 - 1), "burst_px": (DEFAULT_BURST_PX, 1, 1 << 24),
          "hot_dn_per_ms": (DEFAULT_HOT_DN_PER_MS, 1, 1 << 20)}
"""Whole-number parameters of the faults: (default, least, most)."""
def draw(seed: int, kind: str, index: int) -> int:
    """The 64-bit draw for event ``index`` of fault ``kind`` under ``seed``: a pure function, no state."""
    salt = zlib.crc32(kind.encode())
    return splitmix64(splitmix64((seed & MASK64) ^ (salt << 32)) ^ (index & MASK64))


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
    seqrewrite_to: int = 0
    seqskip_by: int = 1
    burst_px: int = DEFAULT_BURST_PX
    hot_dn_per_ms: int = DEFAULT_HOT_DN_PER_MS
    defects: tuple[tuple[str, int], ...] = ()  # (kind, count) for the defects given, in DEFECTS order
    loaderfail_ms: int | None = None
    dnn_us: int | None = None

    def __post_init__(self) -> None:
        for kind, pct in self.rates:
            if kind not in RATES or not 0.0 <= pct <= 100.0:
                raise ConfigError(f"fault rate {kind}={pct!r}: expected one of {RATES} at 0..100 %")
        for kind, count in self.defects:
            if kind not in DEFECTS or not 0 <= count <= MAX_DEFECTS:
                raise ConfigError(f"sensor defect {kind}={count!r}: expected one of {DEFECTS} at 0..{MAX_DEFECTS}")

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
        defects = tuple((k, kw.pop(k)) for k in DEFECTS if k in kw)
        return cls(rates=tuple((k, rates[k]) for k in RATES if k in rates), requests=tuple(requests),
                   defects=defects, **kw)

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
        items += [f"{k}={getattr(self, k)}" for k, (default, _, _) in PARAMS.items() if getattr(self, k) != default]
        items += [f"{k}={n}" for k, n in self.defects]
        if self.disconnect is not None:
            items.append(f"disconnect={self.disconnect}")
        items += [r.to_text() for r in self.requests]
        if self.seqwrap is not None:
            items.append(f"seqwrap={self.seqwrap}")
        if self.tswrap_s is not None:
            items.append(f"tswrap={self.tswrap_s}")
        if self.loaderfail_ms is not None:
            items.append(f"loaderfail={self.loaderfail_ms}")
        if self.dnn_us is not None:
            items.append(f"dnn_us={self.dnn_us}")
        if items and self.seed:
            items.append(f"seed={self.seed}")
        return ",".join(items)

    def __str__(self) -> str:
        return self.to_text() or "none"

    def __bool__(self) -> bool:
        """True when the plan injects anything."""
        return bool(self.rates or self.disconnect is not None or self.requests or self.seqwrap or self.tswrap_s
                    or self.defects or self.insensor_faults)

    @property
    def insensor_faults(self) -> bool:
        """True when the plan has an AI Camera fault (``INSENSOR_FAULTS``) for the in-sensor stage."""
        return self.loaderfail_ms is not None or self.dnn_us is not None or bool(self.rate("fetimeout"))

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

    def defect(self, kind: str) -> int:
        """How many ``kind`` defects (``DEFECTS``) the plan gives the sensor (0 when not given)."""
        return next((n for k, n in self.defects if k == kind), 0)

    @property
    def counter_faults(self) -> bool:
        """True when a frame-counter fault (``COUNTER_FAULTS``) may hit."""
        return any(self.rate(k) for k in COUNTER_FAULTS)

    def first_of(self, kinds: tuple[str, ...], index: int) -> str | None:
        """The first of ``kinds`` that hits event ``index`` (they are drawn independently), or None."""
        return next((k for k in kinds if self.fires(k, index)), None)

    def counter_step(self, previous: int, n: int) -> tuple[int, str | None]:
        """Frame ``n``'s 32-bit counter after frame ``n - 1``'s was ``previous``, and the counter fault that hit
        it (``COUNTER_FAULTS``; frame 0 starts the count and is never hit)."""
        kind = self.first_of(COUNTER_FAULTS, n) if n > 0 else None
        if kind == "seqrewrite":
            return self.seqrewrite_to, kind
        if kind == "seqfreeze":
            return previous, kind
        return (previous + 1 + (self.seqskip_by if kind == "seqskip" else 0)) % U32, kind

    def sequence(self, n: int) -> int:
        """Frame sequence number ``n`` (from 0) as a 32-bit field carries it: shifted toward the wrap by
        ``seqwrap``, with the frame-counter faults of frames 1..n applied (each counts from the counter the
        previous frame showed; ``FaultInjector.sequence`` computes it incrementally)."""
        c = (U32 - self.seqwrap) % U32 if self.seqwrap else 0
        if not self.counter_faults:
            return (c + n) % U32
        for k in range(1, n + 1):
            c, _ = self.counter_step(c, k)
        return c

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
    seq_rewrites: int = 0
    seq_freezes: int = 0
    seq_skips: int = 0
    grey_frames: int = 0
    black_frames: int = 0
    frozen_frames: int = 0
    register_resets: int = 0
    bursts: int = 0  # frames delivered with a pixel-error burst (made by the sensor model)


_COUNTER = {"drop": "dropped", "error": "errors", "corrupt": "corrupted", "delay": "delayed", "stall": "stalls",
            "babble": "babbles", "short": "shorts", "cut": "cuts", "seqrewrite": "seq_rewrites",
            "seqfreeze": "seq_freezes", "seqskip": "seq_skips", "grey": "grey_frames", "black": "black_frames",
            "frozen": "frozen_frames", "regreset": "register_resets", "burst": "bursts"}


@dataclass
class FaultInjector:
    """One transport's use of a plan: the decisions, counted in ``stats`` as they fire, and per-request call
    counts for the one-shot errors. Not thread-safe: a transport asks from the thread that owns the events."""

    plan: FaultPlan = field(default_factory=FaultPlan)
    stats: FaultStats = field(default_factory=FaultStats)

    def __post_init__(self) -> None:
        self._calls: dict[str, int] = {}
        self._counter = (0, self.plan.sequence(0))  # (n, sequence(n)) last asked: counter faults add up

    def __bool__(self) -> bool:
        return bool(self.plan)

    def hit(self, kind: str, index: int, events: str = "") -> bool:
        """``plan.fires(kind, index, events)``, counted when True."""
        if not self.plan.fires(kind, index, events):
            return False
        self.count(kind)
        return True

    def count(self, kind: str) -> None:
        """Count one fault of ``kind`` (a key of the rates) as injected."""
        counter = _COUNTER[kind]
        setattr(self.stats, counter, getattr(self.stats, counter) + 1)

    def first(self, kinds: tuple[str, ...], index: int) -> str | None:
        """``plan.first_of(kinds, index)``, counted when one hits."""
        kind = self.plan.first_of(kinds, index)
        if kind is not None:
            self.count(kind)
        return kind

    def sequence(self, n: int) -> int:
        """``plan.sequence(n)`` for the frame delivered as device frame ``n`` of the stream (from 0), counting the
        counter fault that hit it. Frames are asked in order, so the counter is carried on from the last one asked
        (a smaller ``n``, a new stream, counts again from frame 0)."""
        plan = self.plan
        if not plan.counter_faults:
            return plan.sequence(n)
        k, c = self._counter
        if n < k:
            k, c = 0, plan.sequence(0)
        kind = None
        while k < n:
            k += 1
            c, kind = plan.counter_step(c, k)
        self._counter = (k, c)
        if kind is not None:
            self.count(kind)
        return c

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
        kw["seed"] = _whole(0, MASK64)(_needs(value))
    elif key in PARAMS:
        kw[key] = _whole(*PARAMS[key][1:])(_needs(value))
    elif key in DEFECTS:
        kw[key] = _whole(0, MAX_DEFECTS)(_needs(value))
    elif key == "disconnect":
        kw["disconnect"] = _whole(0, U32)(_needs(value))
    elif key == "seqwrap":
        kw["seqwrap"] = DEFAULT_SEQWRAP if value is None else _whole(1, U32 - 1)(value)
    elif key == "tswrap":
        kw["tswrap_s"] = DEFAULT_TSWRAP_S if value is None else _whole(1, 1 << 32)(value)
    elif key == "loaderfail":
        kw["loaderfail_ms"] = _whole(0, MAX_LOADERFAIL_MS)(_needs(value))
    elif key == "dnn_us":
        kw["dnn_us"] = _whole(1, MAX_DNN_US)(_needs(value))
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


def _whole(lo: int, hi: int) -> Callable[[str], int]:
    """The parser of a whole number in ``lo..hi`` (``expected a whole number in lo..hi`` otherwise)."""
    return bounded(int, lo, hi, "a whole number")


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
    return RequestFault(key, err, _whole(1, U32)(nth) if nth else 1)


def _num(x: float) -> str:
    return f"{x:g}"


def _known() -> list[str]:
    return ["seed", *RATES, *PARAMS, "disconnect", *REQUESTS, "seqwrap", "tswrap", *DEFECTS, "loaderfail", "dnn_us"]


FAULT_COUNTERS = tuple(f.name for f in fields(FaultStats))
"""The names of the ``FaultStats`` counters (for status pages and docs)."""
