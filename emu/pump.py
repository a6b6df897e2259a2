"""Real-time streaming of a FirmwareCamera: a thread that hands each frame's row bands to sinks at their times.

The scene is deterministic, so the pump renders ahead of schedule, as a sensor pipeline is full before its frames
are due: it keeps up to ``ahead`` frames made (the one being read out and the next ones) and, on the camera's clock,
calls every sink's ``on_band`` as each band of lines has been read out, then ``on_frame`` once the last line is out.
A render holds the GIL between its kernels (the renderer's numba kernels release it while they run), so a render
starts only when it will end before the next last line is due (its time estimated as the 90th percentile of the
recent renders, plus a quarter and a margin), and only after the consumers woken by the previous frame have had
``HANDOFF_NS`` to take the GIL; a slow render on a busy machine then costs a frame of the pool, not a dropped
frame. When the spec changes (controls, registers, scene),
frames made ahead whose exposure starts at or after the change are thrown away and made again from the new
spec (``stats.remade``), so a change takes effect at the first frame exposed after it, as on a sensor; a
frame already exposing keeps the settings it started with.

When rendering is slower than the frame rate for longer than the pool lasts, a frame whose readout has
ended is still handed out (late) unless the next one made is due as well; then it is skipped, as are frames
planned after their readout ended: the stream's sequence numbers show the gap, and the camera's
``stats['skipped']`` counts it. A skipped frame's in-sensor results ride on the next frame handed out, so no
result done on the device is lost. An exception on the pump's thread stops it; ``check()`` and
``close()`` re-raise it.
"""

from __future__ import annotations

import collections
import dataclasses
import os
import threading
import time
from dataclasses import dataclass
from typing import Protocol

from rollcam.common.errors import DeviceError
from rollcam.common.lifecycle import Closeable, Stats, Worker
from rollcam.firmware.camera import FirmwareCamera, FramePlan
from rollcam.firmware.spec import CameraSpec
from rollcam.sim.frame import Frame

SPIN_NS = 1_000_000
RENDER_MARGIN_NS = 3_000_000
HANDOFF_NS = 1_000_000
AHEAD = 3
"""Frames the pump keeps made: the one being read out and two more (6 MB each at 1080p BGR)."""


@dataclass
class _Made:
    """A frame made ahead: its plan, the spec it was made from, and the bands already handed out."""

    plan: FramePlan
    spec: CameraSpec
    frame: Frame
    bands_out: int = 0


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
    remade: int = 0  # frames made ahead, thrown away because the spec changed before they started exposing
    late_skipped: int = 0  # frames made for nothing: the next one was due too when their turn came
    min_ahead: int | None = None  # fewest frames made beyond the one being read out, when one was due
    rt: str | None = None  # "SCHED_FIFO N", "refused: ..." or None (not asked for)


class FramePump(Closeable):
    """A thread streaming one camera in real time to any number of sinks; a context manager (``with`` starts
    it)."""

    def __init__(self, camera: FirmwareCamera, *, bands: int = 8, name: str = "rollcam-pump",
                 rt_priority: int | None = None, ahead: int = AHEAD) -> None:
        if bands < 1:
            raise ValueError(f"bands must be >= 1, got {bands!r}")
        if ahead < 1:
            raise ValueError(f"ahead must be >= 1, got {ahead!r}")
        self.ahead = ahead
        self._pool: collections.deque[_Made] = collections.deque()
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

    def _sleep_until(self, device_ns: int, spin: bool = False, spec: CameraSpec | None = None) -> bool:
        """Wait until the camera's clock reads ``device_ns``; False when the pump is stopping, or (given
        ``spec``) when the camera's spec stops being ``spec`` first: frames made ahead may be stale then.

        With ``spin`` (the frame's last band) the last ``SPIN_NS`` are spent yielding rather than asleep: a
        thread woken from a timed sleep on a busy machine waits for a CPU, one already running does not.
        """
        cam = self.camera
        margin = SPIN_NS if spin and not self._rt else 0
        while True:
            if self._stop.is_set():
                return False
            left = device_ns - cam.clock_ns()
            if left <= 0:
                return True
            if spec is not None and cam.spec is not spec:
                return False
            if left > margin:
                with cam.changed:  # a change (or close) notifies
                    if spec is None or cam.spec is spec:
                        cam.changed.wait((left - margin) / 1e9)
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
        cam, pool = self.camera, self._pool
        while not self._stop.is_set():
            if not cam.streaming:
                pool.clear()
                cam.wait_changed(0.05)
                continue
            self._drop_stale()
            if self._may_render():
                plan = cam.plan_next(cam.clock_ns())
                if plan is not None:
                    self._make(plan)
                    continue
            if not pool:
                cam.wait_changed(0.05)  # waiting for a trigger
                continue
            self._deliver_band(pool[0])

    def _make(self, plan: FramePlan) -> None:
        self._realtime(False)
        t0 = self.camera.clock_ns()
        spec, frame = self.camera.make(plan)
        self._render_ns.append(self.camera.clock_ns() - t0)
        self._pool.append(_Made(plan, spec, frame))

    def _may_render(self) -> bool:
        """Room in the pool, no band due, and a render started now ends before the next last line is due; or
        it never would (renders slower than a frame period): then the pool matters more than one frame's
        timing."""
        pool = self._pool
        if not pool:
            return True
        if len(pool) >= self.ahead:
            return False
        cur = pool[0]
        plan, now = cur.plan, self.camera.clock_ns()
        if now >= plan.schedule.band_due_ns(plan.seq, cur.bands_out, self.bands):
            return False  # a band is due: hand it out first
        recent = sorted(self._render_ns)
        budget = 5 * (recent[9 * len(recent) // 10] if recent else 0) // 4 + RENDER_MARGIN_NS
        return now + budget <= plan.due_ns or budget >= plan.schedule.timing.frame_period_ns - HANDOFF_NS

    def _drop_stale(self) -> None:
        """Throw away frames made from a spec that changed before they started exposing; plan them again."""
        cam, pool = self.camera, self._pool
        spec, changed_ns = cam.spec, cam.spec_changed_ns
        for i, made in enumerate(pool):
            if made.spec is not spec and made.bands_out == 0 and made.plan.start_ns >= changed_ns:
                stale = [pool.pop() for _ in range(len(pool) - i)][::-1]
                self.stats.remade += len(stale)
                if cam.trigger_mode == "external":  # triggered starts stay: make the same frames again
                    for m in stale:
                        self._make(m.plan)
                else:
                    cam.rewind(stale[0].plan.seq)
                return

    def _deliver_band(self, made: _Made) -> None:
        """Hand out ``made``'s next band at its time (and the frame after its last band)."""
        cam, plan, pool = self.camera, made.plan, self._pool
        band = made.bands_out
        if band == 0:
            if len(pool) > 1 and cam.clock_ns() > pool[1].plan.due_ns:  # a newer frame is due too: skip this
                skipped = pool.popleft()
                if skipped.frame.insensor:  # the in-sensor results it carried ride on the next frame instead
                    pool[0].frame = dataclasses.replace(
                        pool[0].frame, insensor=skipped.frame.insensor + (pool[0].frame.insensor or ()))
                self.stats.late_skipped += 1
                with cam.lock:
                    cam.stats.skipped += 1
                return
            ahead = len(pool) - 1
            self.stats.min_ahead = ahead if self.stats.min_ahead is None else min(self.stats.min_ahead, ahead)
        due = plan.schedule.band_due_ns(plan.seq, band, self.bands)
        last = band == self.bands - 1
        self._realtime(True)
        # Before the first band, a change of spec wakes the wait: the frame may be stale (see ``_run``).
        if not self._sleep_until(due, spin=last, spec=cam.spec if band == 0 else None):
            return
        made.bands_out += 1
        if not cam.streaming:
            pool.clear()
            return
        for sink in self._sinks:
            sink.on_band(made.frame, plan, band, self.bands)
        if not last:
            return
        pool.popleft()
        self.stats.frames += 1
        self.stats.max_late_ns = max(self.stats.max_late_ns, cam.clock_ns() - plan.due_ns)
        for sink in self._sinks:
            sink.on_frame(made.frame, plan)
        # Let the consumers this frame woke take the GIL before the next render holds it.
        handoff = cam.clock_ns() + HANDOFF_NS
        while cam.clock_ns() < handoff and not self._stop.is_set():
            time.sleep(0.0002)
