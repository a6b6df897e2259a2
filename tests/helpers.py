"""What many tests share: waiting for a condition with a deadline (never a fixed sleep), and a clock the test moves
by hand. tools/one_home.py finds copies of these elsewhere in tests/ (STYLE.md "Wait on events, not sleeps").
The SIGINT helpers live in tests/interrupts.py."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, TypeVar

from rollcam.common.lifecycle import Deadline

T = TypeVar("T")


def wait_for(condition: Callable[[], T], timeout_s: float = 30.0, what: str = "the condition",
             every_s: float = 0.05) -> T:
    """Poll ``condition()`` until it returns something true and return that; fail naming ``what`` once
    ``timeout_s`` has passed (a bound for a loaded machine, not a speed target). The condition is asked once
    more after the deadline, so a slow poll never loses a condition that came true at the end."""
    deadline = Deadline(timeout_s)
    while not deadline.expired:
        got = condition()
        if got:
            return got
        time.sleep(min(every_s, deadline.remaining() or every_s))
    got = condition()
    if got:
        return got
    raise AssertionError(f"timed out after {timeout_s:g} s waiting for {what}")


class FakeClock:
    """A clock the test moves by hand (``clock.t += ...``): calling it returns ``t``, integer ns for a device
    clock or float seconds for a ``Deadline``. ``sleep`` moves it on instead of waiting, so code given
    ``sleep=clock.sleep`` runs in device time."""

    def __init__(self, t: Any = 0) -> None:
        self.t = t

    def __call__(self) -> Any:
        return self.t

    def sleep(self, seconds: float) -> None:
        """Move the clock on by ``seconds``: in ns (at least 1, so a loop that sleeps always moves on) when ``t``
        is an integer device clock, in seconds when it is a float."""
        if isinstance(self.t, int):
            self.t += max(int(seconds * 1e9), 1)
        else:
            self.t += seconds


def metadata_with(picam2: Any, key: str, frames: int = 20) -> dict:
    """The metadata of the first of a started picamera2 camera's next ``frames`` frames that carries ``key`` (an
    in-sensor result or tensor rides on a later frame than its input); fails naming ``key`` if none does."""
    for _ in range(frames):
        metadata = picam2.capture_metadata()
        if metadata.get(key):
            return metadata
    raise AssertionError(f"none of {frames} frames carried {key!r} in its metadata")
