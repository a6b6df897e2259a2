"""Real-time streaming of a FirmwareCamera: a thread that hands each frame's row bands to sinks at their times.

The pump asks the camera which frame is due next, renders it ahead of time, then waits (on the camera's
clock) until each band of lines has been read out and calls every sink's ``on_band``, then ``on_frame``
once the last line is out. A frame whose readout ended before the pump got to it (rendering slower than
the frame rate) is skipped: the stream's sequence numbers show the gap, and the camera's ``stats['skipped']``
counts it. An exception on the pump's thread stops it; ``check()`` and ``close()`` re-raise it.
"""

from __future__ import annotations

import collections
import os
import threading
import time
from dataclasses import dataclass
from typing import Protocol

from rollcam.common.errors import DeviceError
from rollcam.common.lifecycle import Closeable, Stats, Worker
from rollcam.firmware.camera import FirmwareCamera, FramePlan
from rollcam.sim.frame import Frame

SPIN_NS = 1_000_000
RENDER_MARGIN_NS = 3_000_000


class Sink(Protocol):
    """What a pump feeds. Both calls run on the pump's thread and must not block."""

    def on_band(self, frame: Frame, plan: FramePlan, band: int, n_bands: int) -> None:
        """Lines of band ``band`` (readout order) of ``frame`` have been read out."""

    def on_frame(self, frame: Frame, plan: FramePlan) -> None:
        """The whole frame has been read out."""


@dataclass
class PumpStats(Stats):
    """What a pump did: frames delivered, the latest a frame's last band went out, its scheduling policy."""

    frames: int = 0
    max_late_ns: int = 0
    rt: str | None = None  # "SCHED_FIFO N", "refused: ..." or None (not asked for)


class FramePump(Closeable):
    """A thread streaming one camera in real time to any number of sinks; a context manager (``with`` starts
    it)."""

    def __init__(self, camera: FirmwareCamera, *, bands: int = 8, name: str = "rollcam-pump",
                 rt_priority: int | None = None) -> None:
        if bands < 1:
            raise ValueError(f"bands must be >= 1, got {bands!r}")
        self.camera = camera
        self.bands = bands
        self.rt_priority = rt_priority
        self._sinks: list[Sink] = []
        self._lock = threading.Lock()
        self._worker = Worker(self._run, name=name, wrap=DeviceError)
        self._stop = self._worker.stop_event
        self._rt = False
        self._render_ns: collections.deque[int] = collections.deque(maxlen=64)
        self.stats = PumpStats()

    @property
    def error(self) -> BaseException | None:
        """The exception that stopped the pump's thread, or None."""
        return self._worker.error

    def check(self) -> None:
        """Raise (as a DeviceError) the exception that stopped the pump's thread, if one did."""
        self._worker.check()

    def add_sink(self, sink: Sink) -> None:
        """Feed ``sink`` from the next band on."""
        with self._lock:
            self._sinks = [*self._sinks, sink]

    def remove_sink(self, sink: Sink) -> None:
        """Stop feeding ``sink`` (no error if it was not fed)."""
        with self._lock:
            self._sinks = [s for s in self._sinks if s is not sink]

    def start(self) -> None:
        """Start the thread (once; not after close)."""
        self._worker.start()

    _on_enter = start

    def _close(self) -> None:
        """Stop the thread and wait for it; re-raises what stopped it, if anything did."""
        self._worker.stop()
        with self.camera.changed:
            self.camera.changed.notify_all()
        self._worker.close()

    def _sleep_until(self, device_ns: int, spin: bool = False) -> bool:
        """Wait until the camera's clock reads ``device_ns``; False when the pump is stopping.

        With ``spin`` (the frame's last band) the last ``SPIN_NS`` are spent yielding rather than asleep: a
        thread woken from a timed sleep on a busy machine waits for a CPU, one already running does not.
        """
        margin = SPIN_NS if spin and not self._rt else 0
        while True:
            left = device_ns - self.camera.clock_ns()
            if left <= 0:
                return not self._stop.is_set()
            if left > margin:
                if self._stop.wait((left - margin) / 1e9):
                    return False
            else:
                time.sleep(0)

    def _realtime(self, on: bool) -> None:
        """Waits and band deliveries run under SCHED_FIFO (``rt_priority``), rendering under the normal policy."""
        if self.rt_priority is None or on == self._rt:
            return
        try:
            if on:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.rt_priority))
            else:
                os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        except (OSError, AttributeError) as exc:  # not permitted (no CAP_SYS_NICE) or not Linux: run without it
            self.stats.rt = f"refused: {exc}"
            self.rt_priority = None
            return
        self._rt = on
        self.stats.rt = f"SCHED_FIFO {self.rt_priority}"

    def _run(self) -> None:
        cam = self.camera
        while not self._stop.is_set():
            plan = cam.plan_next(cam.clock_ns())
            if plan is None:
                cam.wait_changed(0.05)
                continue
            # Render as late as is safe (1.5x the slowest recent render, plus a margin, before the first band
            # is due), so that readers woken by the previous frame get the GIL before the render takes it.
            budget = 3 * max(self._render_ns, default=0) // 2 + RENDER_MARGIN_NS
            if not self._sleep_until(plan.schedule.band_due_ns(plan.seq, 0, self.bands) - budget):
                return
            self._realtime(False)
            t0 = cam.clock_ns()
            frame = cam.render(plan)
            self._render_ns.append(cam.clock_ns() - t0)
            self._realtime(True)
            for band in range(self.bands):
                due = plan.schedule.band_due_ns(plan.seq, band, self.bands)
                if not self._sleep_until(due, spin=band == self.bands - 1):
                    return
                if not cam.streaming:
                    break
                for sink in self._sinks:
                    sink.on_band(frame, plan, band, self.bands)
            else:
                late = cam.clock_ns() - plan.due_ns
                self.stats.frames += 1
                self.stats.max_late_ns = max(self.stats.max_late_ns, late)
                for sink in self._sinks:
                    sink.on_frame(frame, plan)
                time.sleep(0)  # let woken consumers take the GIL before the next render holds it
