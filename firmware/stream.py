"""The stream side of the emulated camera: device clock, stream on/off, trigger mode and the frame plan.

``DeviceStream`` is the half of ``FirmwareCamera`` that says which frame is due next and when, in integer ns
of the device clock (the host clock passed in minus the boot time). It reads the frame timing from the
camera's current ``CameraSpec``; timing changes apply from the next frame, whose schedule is re-anchored at
that frame's start.

External triggers follow a sensor's trigger input with one latch: a trigger while the sensor is idle starts
a frame at once; a trigger while a triggered frame is exposing or being read out is latched, and its frame
starts the moment that readout ends; further triggers while one is latched are ignored (counted in
``stats.triggers_ignored``). So triggers cost nothing however fast they come: at most one frame in progress
and one latched. A consumer that falls behind loses the oldest unmade frame (``stats.skipped``).
"""

from __future__ import annotations

import collections
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from rollcam.common.errors import ConfigError, DeviceError
from rollcam.common.lifecycle import Stats

from .scheduler import FrameSchedule
from .spec import CameraSpec

Clock = Callable[[], int]
"""A monotonic host clock in integer ns (``time.monotonic_ns`` by default; tests pass their own)."""


@dataclass
class CameraStats(Stats):
    """What a device has done: frames made, frames skipped because they were late, external triggers,
    in-sensor inferences run and frames the in-sensor accelerator was too busy for, injected tensors run and missed
    (their comparison frame skipped), the AI Camera's firmware loader failures and front-end timeouts (injected
    faults, ``rollcam.firmware.insensor_stage``), and register resets (an
    injected fault, ``rollcam.firmware.labfaults``)."""

    frames: int = 0
    skipped: int = 0
    triggers: int = 0
    triggers_ignored: int = 0
    insensor_runs: int = 0
    insensor_skipped: int = 0
    insensor_injected: int = 0
    insensor_injections_missed: int = 0
    loader_failures: int = 0
    frontend_timeouts: int = 0
    register_resets: int = 0


@dataclass(frozen=True)
class FramePlan:
    """The next frame to make: its sequence number and the schedule that says when its lines are due."""

    seq: int
    schedule: FrameSchedule

    @property
    def start_ns(self) -> int:
        """Start of exposure of the first line (device clock)."""
        return self.schedule.start_ns(self.seq)

    @property
    def due_ns(self) -> int:
        """Time the frame is complete (its last line read out)."""
        return self.schedule.frame_due_ns(self.seq)


def schedule_of(spec: CameraSpec, epoch_ns: int, first_seq: int = 0) -> FrameSchedule:
    """The schedule of ``spec``'s frames: frame ``first_seq`` starts exposing at ``epoch_ns``."""
    s = spec.settings
    return FrameSchedule(s.timing, epoch_ns, first_seq, s.exposure_ns, s.n_lines, s.shutter == "rolling")


class DeviceStream:
    """Stream state, trigger and frame planning over a ``spec`` attribute the subclass keeps."""

    spec: CameraSpec

    def __init__(self, clock: Clock | None, boot_ns: int | None = None) -> None:
        self.clock = clock or time.monotonic_ns
        self.boot_ns = self.clock() if boot_ns is None else int(boot_ns)  # the clock's reading at device time 0
        self.lock = threading.RLock()
        self.changed = threading.Condition(self.lock)
        self.streaming = False
        self.trigger_mode = "free"
        self.stats = CameraStats()
        self._triggers: collections.deque[int] = collections.deque()  # starts of triggered frames not yet planned
        self._busy_until_ns = 0  # end of readout of the last triggered frame (device clock)
        self._latched_start_ns = -1  # start of the latched frame, while one is latched
        self._schedule: FrameSchedule | None = None
        self._next_seq = 0
        self._hold_seq: int | None = None  # a frame that is made even when late (a tensor was injected for it)
        self.spec_changed_ns = -1  # device time the spec last changed (frames exposed from then on follow it)

    def _spec_for_frame(self) -> CameraSpec:
        """The spec a frame is made from now, counted in ``stats.frames`` (a frame made ahead is stale once the
        spec changes before its exposure starts: ``spec_changed_ns``)."""
        with self.lock:
            self.stats.frames += 1
            return self.spec

    def _commit(self, spec: CameraSpec) -> None:
        """Make ``spec`` the spec (under the lock), noting when it changed, and wake whoever waits on a change."""
        if spec != self.spec:
            self.spec_changed_ns = self.clock_ns()
        self.spec = spec
        self.changed.notify_all()

    def clock_ns(self) -> int:
        """Device clock: integer ns since the device booted."""
        return self.clock() - self.boot_ns

    def host_ns(self, device_ns: int) -> int:
        """The host clock reading of a device time (for pacing)."""
        return device_ns + self.boot_ns

    @property
    def next_seq(self) -> int:
        """Sequence number the next planned frame gets (it counts across stream starts)."""
        return self._next_seq

    def _warm(self) -> None:
        """Called before the clock starts (the subclass builds its renderer here)."""

    def stream_on(self) -> None:
        """Start streaming: frame ``next seq`` starts exposing now (device clock). Idempotent."""
        with self.changed:
            if not self.streaming:
                self._warm()
                self.streaming = True
                self._schedule = schedule_of(self.spec, self.clock_ns(), self._next_seq)
                self.changed.notify_all()

    def stream_off(self) -> None:
        """Stop streaming; frames not yet planned are never made. Idempotent."""
        with self.changed:
            self.streaming = False
            self._clear_triggers()
            self.changed.notify_all()

    def set_trigger_mode(self, mode: str) -> None:
        """``free`` (frames back to back) or ``external`` (one frame per ``trigger()``)."""
        if mode not in ("free", "external"):
            raise ConfigError(f"trigger mode {mode!r} is not 'free' or 'external'")
        with self.changed:
            self.trigger_mode = mode
            self._clear_triggers()
            if self.streaming:
                self._schedule = schedule_of(self.spec, self.clock_ns(), self._next_seq)
            self.changed.notify_all()

    def _clear_triggers(self) -> None:
        self._triggers.clear()
        self._busy_until_ns, self._latched_start_ns = 0, -1

    def trigger(self, at_ns: int | None = None) -> int | None:
        """An external trigger pulse (trigger mode external, streaming): starts a frame now (or at device time
        ``at_ns``, the pulse's edge as a rig's trigger line stamps it), or latches one to start when the frame in
        progress is read out, or is ignored while one is latched. Returns the exposure start of the frame it
        starts (device ns), or None when it was ignored."""
        with self.changed:
            if self.trigger_mode != "external":
                raise DeviceError("trigger needs trigger mode 'external' (TRIGMODE EXTERNAL)")
            if not self.streaming:
                raise DeviceError("trigger while not streaming (STREAM ON first)")
            now = self.clock_ns() if at_ns is None else int(at_ns)
            if now < self._latched_start_ns:
                self.stats.triggers_ignored += 1
                return None
            start = max(now, self._busy_until_ns)
            if start > now:
                self._latched_start_ns = start
            self._busy_until_ns = schedule_of(self.spec, start, 0).frame_due_ns(0)
            if len(self._triggers) >= 2:  # the consumer is two frames behind: the oldest is lost, as on a sensor
                self._triggers.popleft()
                self.stats.skipped += 1
            self._triggers.append(start)
            self.stats.triggers += 1
            self.changed.notify_all()
            return start

    def current_schedule(self) -> FrameSchedule | None:
        """The schedule frames follow from the next one on (timing changes included), or None when idle."""
        with self.lock:
            if not self.streaming or self._schedule is None:
                return None
            sched = self._schedule
            fresh = schedule_of(self.spec, sched.start_ns(self._next_seq), self._next_seq)
            if (fresh.timing, fresh.exposure_ns, fresh.rolling) != (sched.timing, sched.exposure_ns, sched.rolling):
                sched = self._schedule = fresh
            return sched

    def plan_next(self, now_ns: int | None = None) -> FramePlan | None:
        """The next frame to make, or None (not streaming, or waiting for a trigger).

        Timing changes take effect from the next frame. With ``now_ns`` (device clock), a free-running stream
        skips the frames whose readout already ended before ``now_ns`` (counted in ``stats.skipped``).
        """
        with self.lock:
            if not self.streaming or self._schedule is None:
                return None
            seq = self._next_seq
            if self.trigger_mode == "external":
                if not self._triggers:
                    return None
                sched = schedule_of(self.spec, self._triggers.popleft(), seq)
            else:
                sched = self.current_schedule()
                assert sched is not None
                if now_ns is not None:
                    late = sched.first_due_from(seq, now_ns)
                    if self._hold_seq is not None and seq <= self._hold_seq:
                        late = min(late, self._hold_seq)
                    self.stats.skipped += late - seq
                    seq = late
            if self._hold_seq is not None and seq >= self._hold_seq:
                self._hold_seq = None
            self._next_seq = seq + 1
            return FramePlan(seq, sched)

    def hold(self, seq: int | None = None) -> int:
        """Make frame ``seq`` (default: the next one planned) even if it is late when it is planned: a free-running
        stream skips no further than it (a tensor was injected for it, and a real sensor makes every frame).
        Returns the frame's sequence number."""
        with self.lock:
            held = self._next_seq if seq is None else max(seq, self._next_seq)
            self._hold_seq = held
            return held

    def rewind(self, seq: int) -> None:
        """Plan frame ``seq`` again next (a free-running consumer that planned ahead and threw the frames from
        ``seq`` on away, because the spec changed before they started exposing): the schedule re-anchors at
        that frame's start if the timing changed. Never moves forward."""
        with self.lock:
            self._next_seq = min(self._next_seq, seq)

    def note_made(self, seq: int) -> None:
        """Record that frame ``seq`` was planned by a consumer that does not use ``plan_next`` (UVC), so the
        next timing change re-anchors the schedule after it rather than at the stream's start."""
        with self.lock:
            self._next_seq = max(self._next_seq, seq + 1)

    def wait_changed(self, timeout_s: float) -> None:
        """Block until a control, the stream state or a trigger changes, or ``timeout_s`` passes."""
        with self.changed:
            self.changed.wait(timeout_s)
