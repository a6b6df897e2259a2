"""Real-time frame delivery as a sensor does it: frames are made on their own thread whether or not the host
reads, and the newest completed one waits for the host.

Frame ``i`` is rendered and encoded while frame ``i-1`` is read out (from frame ``i-1``'s due time on), and
is offered at its own due time, so a host that keeps up gets each frame as it falls due instead of waiting
for its render. One frame waits in the slot: a frame the host has not taken when the next one completes is
replaced by it (its in-sensor results ride on the frame that replaced it), and a renderer that falls behind
skips to the newest frame due; both count as dropped.
"""

from __future__ import annotations

import contextlib
import dataclasses
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from rollcam.common.errors import DeviceError
from rollcam.common.lifecycle import Worker
from rollcam.sim.frame import Frame

from .producer import FrameProducer

POLL_NS = 200_000  # how often a waiting host looks again when nothing is ready
MAX_WAIT_S = 0.05  # the renderer's longest single sleep, so stop() is prompt


class RenderAhead:
    """A renderer thread and a one-frame slot between a ``FrameProducer`` and a streaming endpoint."""

    def __init__(self, producer: FrameProducer, encode: Callable[[Frame], np.ndarray], stats: Any,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        self.producer, self._encode, self.stats, self._sleep = producer, encode, stats, sleep
        self._cond = threading.Condition()
        self._slot: tuple[int, Frame, np.ndarray] | None = None
        self._next_due = producer.frame_due_ns(0)
        self._stopped = False
        self._worker = Worker(self._run, name="uvc-render-ahead", wrap=DeviceError)
        self._worker.start()

    def take(self) -> tuple[int, Frame, np.ndarray] | int:
        """The newest completed frame (index, frame, encoded bytes), or the ns to wait before asking again."""
        self._worker.check()  # a render that failed fails the host's reads from now on
        with self._cond:
            if self._slot is None:
                return max(self._next_due - self.producer.now_ns(), POLL_NS)
            got, self._slot = self._slot, None
            return got

    def stop(self) -> None:
        """Stop the renderer thread (it finishes the frame it is on, if any); safe to call twice. A render
        error the host was never told of (it stopped reading first) is not raised here: stopping must work."""
        with self._cond:
            self._stopped = True
            self._cond.notify_all()
        with contextlib.suppress(DeviceError):  # take() reports it to a host still reading; this one stopped
            self._worker.close()

    def _wait_until(self, t_ns: int) -> bool:
        while not self._stopped:
            left = t_ns - self.producer.now_ns()
            if left <= 0:
                return True
            self._sleep(min(left / 1e9, MAX_WAIT_S))
        return False

    def _run(self) -> None:
        p = self.producer
        i = 0
        while not self._stopped:
            if i and not self._wait_until(p.frame_due_ns(i - 1)):
                return
            now = p.now_ns()
            if p.frame_due_ns(i) <= now:  # the renderer fell behind: the sensor does not queue frames
                newest = newest_due(p, i, now)
                self.stats.frames_dropped += newest - i
                i = newest
            frame = p.frame(i)
            data = self._encode(frame)
            with self._cond:
                self._next_due = p.frame_due_ns(i)
            if not self._wait_until(self._next_due):
                return
            with self._cond:
                if self._slot is not None:
                    self.stats.frames_dropped += 1  # the host never took the previous frame
                    if self._slot[1].insensor:  # its in-sensor results ride on this one instead
                        frame = dataclasses.replace(
                            frame, insensor=self._slot[1].insensor + (frame.insensor or ()))
                self._slot = (i, frame, data)
                self._next_due = p.frame_due_ns(i + 1)
            i += 1


def newest_due(p: FrameProducer, index: int, now_ns: int) -> int:
    """The last frame index >= ``index`` already due at ``now_ns`` (galloping then bisecting: any gap is cheap)."""
    step = 1
    while p.frame_due_ns(index + step) <= now_ns:
        step *= 2
    lo, hi = index + step // 2, index + step  # due(lo) <= now < due(hi)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if p.frame_due_ns(mid) <= now_ns else (lo, mid)
    return lo
