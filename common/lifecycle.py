"""Lifecycle helpers every device, source, server and thread of rollcam shares.

- ``Closeable``: ``close()`` runs the subclass's ``_close()`` exactly once, from any thread; closing twice is
  harmless; ``with`` closes; ``closed`` tells; ``_check_open()`` refuses work on a closed object clearly.
- ``Worker``: a named daemon thread that keeps the exception its function raised, so the owner re-raises it
  (``check()`` at any time, ``close()``/``join()`` at the end) instead of a traceback lost on stderr.
- ``Deadline``: a point in time on a replaceable clock (``time.monotonic`` unless told otherwise), so waits
  are written once and tests run them on a fake clock.
- ``Stats``: the base of the counters objects keep (``@dataclass`` subclasses), with ``to_json()``.

The idea of a lifecycle base comes from linuxpy's ``ReentrantOpen``, that of a deadline object with a
replaceable clock from pyserial's ``Timeout``.
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from collections.abc import Callable
from typing import Any, TypeVar

from .errors import DeviceError, RollcamError

_C = TypeVar("_C", bound="Closeable")
_FLAG_LOCK = threading.Lock()  # guards only the closed flag's check-and-set; close work runs outside it


class Closeable:
    """Base of anything that holds a resource: ``close()`` is idempotent and thread-safe, ``with`` closes.

    Subclasses put their release work in ``_close()`` (called once, by the first ``close()``; later calls
    return at once) and may override ``_on_enter()`` to start work when a ``with`` block begins (a failure
    there closes the object before the error propagates). ``closed_error`` is the exception type
    ``_check_open()`` raises; ``_describe()`` names the object in that message.
    """

    _closed: bool = False  # a class default, so subclasses need not call Closeable.__init__
    closed_error: type[RollcamError] = DeviceError

    @property
    def closed(self) -> bool:
        """True once ``close()`` has been called."""
        return self._closed

    def close(self) -> None:
        """Release what the object holds; safe to call twice and from several threads."""
        with _FLAG_LOCK:
            if self._closed:
                return
            self._closed = True
        self._close()

    def _close(self) -> None:
        """Release work of the subclass; runs once."""

    def _on_enter(self) -> None:
        """Work a ``with`` block starts (a server's threads, say); nothing by default."""

    def _describe(self) -> str:
        return type(self).__name__

    def _check_open(self) -> None:
        """Raise ``closed_error`` naming the object when it has been closed."""
        if self._closed:
            raise self.closed_error(f"{self._describe()} is closed")

    def __enter__(self: _C) -> _C:
        self._check_open()
        try:
            self._on_enter()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Worker(Closeable):
    """A named daemon thread running ``target(*args)`` that keeps the first exception it raises.

    ``stop()`` sets ``stop_event`` (the target polls ``stopping`` or waits on the event; pass an existing
    event to share it). ``check()`` re-raises a kept error at any time (for a consumer that polls the
    thread's results); ``join()`` waits and re-raises; ``close()`` stops, joins and re-raises once. With
    ``wrap`` (a ``RollcamError`` type) the error is re-raised as ``wrap("NAME failed: ...")`` from the
    original, otherwise as it is.
    """

    def __init__(self, target: Callable[..., Any], *args: Any, name: str, wrap: type[RollcamError] | None = None,
                 stop_event: threading.Event | None = None, join_timeout_s: float | None = 5.0) -> None:
        self.name, self.wrap, self.join_timeout_s = name, wrap, join_timeout_s
        self.stop_event = stop_event or threading.Event()
        self._target, self._args = target, args
        self._error: BaseException | None = None
        self._raised = False
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def __repr__(self) -> str:
        state = "failed" if self._error else "alive" if self.alive else "closed" if self.closed else "idle"
        return f"<Worker {self.name!r} {state}>"

    def _describe(self) -> str:
        return f"worker {self.name!r}"

    @property
    def error(self) -> BaseException | None:
        """The exception the target raised, or None."""
        return self._error

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    @property
    def stopping(self) -> bool:
        """True once ``stop()`` (or ``close()``) was called."""
        return self.stop_event.is_set()

    def start(self) -> Worker:
        """Start the thread (a no-op when it already ran or the worker is closed); returns the worker."""
        if not self._closed and self._thread.ident is None:
            self._thread.start()
        return self

    _on_enter = start

    def stop(self) -> None:
        """Ask the target to finish (sets ``stop_event``); does not wait."""
        self.stop_event.set()

    def _run(self) -> None:
        try:
            self._target(*self._args)
        except BaseException as exc:  # kept for the owner: a thread's traceback on stderr helps nobody
            self._error = exc

    def check(self) -> None:
        """Re-raise the target's exception if it raised one."""
        exc = self._error
        if exc is None:
            return
        self._raised = True
        if self.wrap is None or isinstance(exc, self.wrap):
            raise exc
        raise self.wrap(f"{self.name} failed: {exc!r}") from exc

    def join(self, timeout_s: float | None = None) -> bool:
        """Wait for the thread (at most ``timeout_s``); re-raise its exception; True once it has ended."""
        if self._thread.ident is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout_s)
        self.check()
        return not self._thread.is_alive()

    def _close(self) -> None:
        self.stop()
        if self._thread.ident is not None and self._thread is not threading.current_thread():
            self._thread.join(self.join_timeout_s)
        if not self._raised:  # an error the owner already saw through check() is not raised again
            self.check()


class Deadline:
    """A point in time ``seconds`` from now on ``clock`` (``time.monotonic`` unless given), or never.

    ``remaining()`` is what a timed wait takes (None for a deadline that never comes, never negative);
    ``expired`` says whether it has passed; ``restart()`` moves it ``seconds`` past the clock's present.
    """

    def __init__(self, seconds: float | None, clock: Callable[[], float] = time.monotonic) -> None:
        if seconds is not None and (math.isnan(seconds) or seconds < 0):
            raise ValueError(f"a deadline needs a duration >= 0 or None, got {seconds!r}")
        self.seconds, self.clock = seconds, clock
        self._end: float | None = None
        self.restart()

    @classmethod
    def forever(cls, clock: Callable[[], float] = time.monotonic) -> Deadline:
        """A deadline that never expires."""
        return cls(None, clock)

    def __repr__(self) -> str:
        left = self.remaining()
        return "Deadline(forever)" if left is None else f"Deadline({left:.3f} s left of {self.seconds:g})"

    @property
    def infinite(self) -> bool:
        return self._end is None

    def restart(self) -> None:
        """Start the same duration over from the clock's present."""
        self._end = None if self.seconds is None or math.isinf(self.seconds) else self.clock() + self.seconds

    @property
    def expired(self) -> bool:
        """True once the clock has reached the deadline."""
        return self._end is not None and self.clock() >= self._end

    def remaining(self) -> float | None:
        """Seconds left (0 once expired), or None when the deadline never comes."""
        return None if self._end is None else max(self._end - self.clock(), 0.0)

    def within(self, seconds: float) -> float:
        """``seconds`` or the time left, whichever is shorter (for a wait that must also wake to poll)."""
        left = self.remaining()
        return seconds if left is None else min(seconds, left)


class Stats:
    """Base of a component's counters: subclasses are ``@dataclass``es of plain values; ``to_json()`` gives
    the dict that status pages, benchmarks and logs print (field names are the keys)."""

    def to_json(self) -> dict[str, Any]:
        """The counters as a plain dict (a copy: later counting does not change it)."""
        return dataclasses.asdict(self)  # type: ignore[call-overload]
