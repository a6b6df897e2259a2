"""Faults of the MJPEG stream (``http_mjpeg.MjpegServer``), as a failing network camera shows them to clients.

``StreamFaults`` applies a ``rollcam.common.faults.FaultPlan`` to each part before it is offered to the
streams, decided by the part's frame sequence number (so a plan hits the same frames in every run):

- ``drop``: the part is never sent; the next part's ``X-Sequence`` shows the gap.
- ``delay`` (``delay_ms``): the stream stalls; no part goes out for ``delay_ms``, then the held part comes
  (the frames meanwhile are lost: a gap in ``X-Sequence`` and in arrival time).
- ``cut``: the part is cut off after a seeded number of bytes and every stream's connection closes: the client
  reads a part shorter than its ``Content-Length`` and then end of file.
- ``disconnect=N``: after N parts the streams end at a part boundary (the camera went away); a client that
  connects again is served as before.
- ``seqwrap`` / ``tswrap``: ``X-Sequence`` counts in 32 bits from near its wrap, ``X-Timestamp-Ns`` in
  signed 64 bits from near its wrap.
- ``seqrewrite`` / ``seqfreeze`` / ``seqskip``: ``X-Sequence`` is the faulted frame counter.

The image faults (``grey``, ``black``, ``frozen``) and register resets are applied to the frame before it is
encoded (``rollcam.firmware.labfaults``, in ``MjpegServer``), so a snapshot taken then shows them too.

After a cut or a disconnect no part goes out for ``REPLUG_S`` (the camera is away), so the final part is the
last every stream gets. Snapshots (``/snapshot.jpg``) are not faulted. Everything here runs on the server's
event loop.
"""

from __future__ import annotations

import asyncio
import dataclasses
from collections.abc import Callable
from typing import Any

from rollcam.common.faults import FaultInjector

REPLUG_S = 0.5


class StreamFaults:
    """The fault filter between the encoder and the stream slots; ``offer`` is where parts go on."""

    def __init__(self, injector: FaultInjector, offer: Callable[[Any], None], loop: asyncio.AbstractEventLoop,
                 part_type: type) -> None:
        self.injector, self.offer, self.loop, self.part_type = injector, offer, loop, part_type
        self.published = 0
        self._held_until: float | None = None
        self._ts0: int | None = None  # the first part's timestamp (an injected wrap counts from it)

    def publish(self, part: Any) -> None:
        """Offer ``part`` to the streams as the plan says: dropped, held, cut, wrapped or as it is."""
        inj, plan = self.injector, self.injector.plan
        if not plan:
            self.offer(part)
            return
        if self._held_until is not None:
            if self.loop.time() < self._held_until:
                return  # the stream is stalled: frames made meanwhile never go out
            self._held_until = None
        seq = part.sequence
        if inj.hit("drop", seq):
            return
        part = self._wrapped(part)
        self.published += 1
        if inj.disconnect_due(self.published):  # the N-th part is the last
            part = dataclasses.replace(part, final=True)
        elif inj.hit("cut", seq):
            keep = plan.pick("cut", seq, len(part.chunk) - 1) + 1
            part = dataclasses.replace(part, chunk=part.chunk[:keep], final=True)
        if part.final:  # before a delay: the streams end and stay away for REPLUG_S, held part or not
            self._held_until = self.loop.time() + REPLUG_S
        if inj.hit("delay", seq):
            self._held_until = max(self._held_until or 0.0, self.loop.time() + plan.delay_ms / 1000)
            self.loop.call_later(plan.delay_ms / 1000, self.offer, part)
            return
        self.offer(part)

    def _wrapped(self, part: Any) -> Any:
        plan = self.injector.plan
        if not (plan.seqwrap or plan.tswrap_s or plan.counter_faults):
            return part
        headers = dict(part.headers)
        seq = self.injector.sequence(int(headers["X-Sequence"]))
        headers["X-Sequence"] = str(seq)
        t_ns = int(headers["X-Timestamp-Ns"])
        if self._ts0 is None:
            self._ts0 = t_ns
        headers["X-Timestamp-Ns"] = str(plan.timestamp_ns(t_ns, self._ts0))
        return self.part_type(part.sequence, part.jpeg, tuple(headers.items()))
