"""V4L2 events of one open file: control-change subscriptions and the pending queue (v4l2-event.c).

A control's change (value, flags or range) is queued for every file subscribed to it; a new change of the
same control merges into the one still pending, as the kernel's one-element control subscriptions do. The
file that set a value hears of it only with ``ALLOW_FEEDBACK``. Control changes are found by comparing the
controls before and after a request (``diff``), whichever door changed them.
"""

from __future__ import annotations

import collections
import errno
import time
from dataclasses import dataclass

from .ctrls import Ctrl
from .queue import V4L2Error

EVENT_CTRL = 3
SUB_SEND_INITIAL, SUB_ALLOW_FEEDBACK = 1, 2
CH_VALUE, CH_FLAGS, CH_RANGE = 1, 2, 4
WRITE_ONLY = 0x0040


@dataclass
class PendingEvent:
    """One pending control event (the kernel's ``v4l2_kevent``): DQEVENT makes ``raw.Event`` of it."""

    id: int
    changes: int
    ctrl: Ctrl
    sequence: int = 0
    timestamp_ns: int = 0


def diff(before: dict[int, Ctrl], after: dict[int, Ctrl]) -> dict[int, int]:
    """Control id -> V4L2_EVENT_CTRL_CH_* bits of what changed between two snapshots."""
    out = {}
    for cid, a in after.items():
        b = before.get(cid)
        if b is None:
            continue
        ch = (CH_VALUE if a.value != b.value else 0) | (CH_FLAGS if a.flags != b.flags else 0) | \
             (CH_RANGE if (a.minimum, a.maximum, a.step, a.default) != (b.minimum, b.maximum, b.step, b.default)
              else 0)
        if ch:
            out[cid] = ch
    return out


class Events:
    """Subscriptions and pending events of one file handle."""

    def __init__(self, limit: int = 64) -> None:
        self.subs: dict[int, int] = {}  # control id -> subscription flags
        self.pending: collections.OrderedDict[int, PendingEvent] = collections.OrderedDict()
        self.limit = limit
        self.sequence = 0

    def subscribe(self, kind: int, cid: int, flags: int, ctrl: Ctrl | None) -> None:
        """VIDIOC_SUBSCRIBE_EVENT: control events only; SEND_INITIAL queues the current state at once."""
        if kind != EVENT_CTRL or ctrl is None:
            raise V4L2Error(errno.EINVAL, f"cannot subscribe to event type {kind} id {cid:#x}")
        new = cid not in self.subs
        self.subs[cid] = flags
        if new and flags & SUB_SEND_INITIAL and not ctrl.flags & WRITE_ONLY:
            self.queue(ctrl, CH_VALUE | CH_FLAGS)

    def unsubscribe(self, kind: int, cid: int) -> None:
        """VIDIOC_UNSUBSCRIBE_EVENT (type 0: every subscription)."""
        if kind == 0:
            self.subs.clear()
            self.pending.clear()
        elif kind == EVENT_CTRL:
            self.subs.pop(cid, None)
            self.pending.pop(cid, None)

    def queue(self, ctrl: Ctrl, changes: int) -> None:
        """Queue (or merge into the pending) change event of ``ctrl``."""
        old = self.pending.pop(ctrl.id, None)
        if old is not None:
            changes |= old.changes
        elif len(self.pending) >= self.limit:
            self.pending.popitem(last=False)  # the oldest is lost, as when the kernel's ring is full
        self.sequence += 1
        self.pending[ctrl.id] = PendingEvent(ctrl.id, changes, ctrl, self.sequence - 1, time.monotonic_ns())

    def notify(self, changed: dict[int, int], table: dict[int, Ctrl], by_me: bool) -> None:
        """Queue the changes of subscribed controls; a value this file set itself only with ALLOW_FEEDBACK."""
        for cid, ch in changed.items():
            if cid not in self.subs:
                continue
            if by_me and not self.subs[cid] & SUB_ALLOW_FEEDBACK:
                ch &= ~CH_VALUE
            if ch:
                self.queue(table[cid], ch)

    def dequeue(self) -> tuple[PendingEvent, int]:
        """VIDIOC_DQEVENT: the oldest event and how many remain; ENOENT when none is pending."""
        if not self.pending:
            raise V4L2Error(errno.ENOENT, "no event pending")
        _, ev = self.pending.popitem(last=False)
        return ev, len(self.pending)
