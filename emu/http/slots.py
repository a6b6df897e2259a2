"""Fair slots for long-lived HTTP responses (MJPEG streams): no idle client can lock out a live one.

Every stream holds a ``StreamClient``: a two-item mailbox on the event loop (the two newest items not yet
sent; a third replaces the older, and that counts as a drop, so a slow client skips frames and never queues
more than two, while one that keeps up rides out two parts published back to back by an event loop that was
kept from running for a frame) and the time its current write began. A write that has not drained for
``stall_s`` marks the client *stalled*. ``StreamSlots`` admits a newcomer under ``max_streams`` in all and
``max_streams_per_peer`` per address; when a limit is reached it evicts the longest-stalled client inside that
limit; when none is stalled the newcomer waits up to ``admit_wait_s`` (a silent reader stalls within about
``stall_s`` once its capped buffers are full) and is refused only then. ``sweep()`` closes clients stalled
past ``send_timeout_s`` whoever is waiting. A stream that pulls its items (the JSON-lines endpoints) counts
as stalled from the last item it sent: a reader that gets nothing (one asking for a device time far in the
future) yields its slot and is closed by ``sweep()`` as a silent MJPEG reader is. Items are shared by every
client (the same bytes object is written to each transport), so a stalled client costs at most its transport's
write buffer: the high-water mark plus one item.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Any

from .server import Connection, HttpLimits

ADMIT_POLL_S = 0.1  # how often a waiting newcomer looks for a stalled or freed slot


class StreamClient:
    """One stream's state on the event loop: the newest item not yet sent, counters, the write in progress."""

    def __init__(self, key: int, conn: Connection) -> None:
        self.key, self.conn, self.peer = key, conn, conn.peer
        self.item: Any = None  # the newest item not yet sent
        self.older: Any = None  # the one before it, not yet sent either
        self.sent = self.dropped = 0
        self.writing_since: float | None = None
        self.idle_since: float | None = None  # a pulling stream: when it last sent an item (None: never idle)
        self.gone = False
        self._wake = asyncio.Event()

    def offer(self, item: Any) -> None:
        """Queue ``item`` to send after the one not yet sent (if two wait, the older is dropped and counted)."""
        if self.item is not None:
            self.dropped += self.older is not None
            self.older = self.item
        self.item = item
        self._wake.set()

    def evict(self) -> None:
        """Mark the stream gone and wake its sender, whose ``next`` then returns None."""
        self.gone = True
        self._wake.set()

    async def next(self) -> Any:
        """The next item to send, oldest first; None once the client was evicted."""
        while self.item is None and not self.gone:
            self._wake.clear()
            await self._wake.wait()
        if self.older is not None:
            item, self.older = self.older, None
        else:
            item, self.item = self.item, None
        return None if self.gone else item

    async def send(self, write: Callable[[bytes], Awaitable[None]], data: bytes, now: Callable[[], float]) -> None:
        """``await write(data)``, timed: while it waits for the client to drain, the client may be stalled."""
        self.writing_since = now()
        try:
            await write(data)
        finally:
            self.writing_since = None
        self.sent += 1
        if self.idle_since is not None:
            self.idle_since = now()

    def stalled_s(self, now: float) -> float:
        """How long the current write has waited, or a pulling stream has sent nothing (0 when neither)."""
        since = [t for t in (self.writing_since, self.idle_since) if t is not None]
        return now - min(since) if since else 0.0

    def backlog_bytes(self) -> int:
        """Bytes written but not yet taken by the kernel."""
        t = self.conn.transport
        return t.get_write_buffer_size() if t is not None and not t.is_closing() else 0

    def to_json(self, now: float) -> dict[str, Any]:
        return {"peer": self.peer, "sent": self.sent, "dropped": self.dropped,
                "stalled_s": round(self.stalled_s(now), 3), "backlog_bytes": self.backlog_bytes()}


class StreamSlots:
    """The streams being served, admitted fairly under ``limits``; every method runs on the event loop."""

    def __init__(self, limits: HttpLimits, clock: Callable[[], float]) -> None:
        self.limits, self.clock = limits, clock
        self.clients: dict[int, StreamClient] = {}
        self.served = self.evicted = self.send_timeouts = self.dropped_total = 0

    def __len__(self) -> int:
        return len(self.clients)

    def __iter__(self) -> Any:
        return iter(list(self.clients.values()))

    async def admit(self, conn: Connection, *, pulls: bool = False) -> StreamClient | str:
        """A slot for a stream on ``conn``, waiting up to ``admit_wait_s`` for one, or why there is none."""
        end = self.clock() + self.limits.admit_wait_s
        while isinstance(got := self.join(conn, pulls=pulls), str) and self.clock() < end and not conn.eof:
            await asyncio.sleep(ADMIT_POLL_S)
        return got

    def join(self, conn: Connection, *, pulls: bool = False) -> StreamClient | str:
        """A slot for a stream on ``conn`` now, or why there is none (for a 503); ``pulls``: the stream finds its
        own items (and is idle, so evictable, while it finds none), rather than being offered them."""
        lim, now = self.limits, self.clock()
        for limit, why, mine in ((lim.max_streams_per_peer, f"too many streams from {conn.peer}", True),
                                 (lim.max_streams, "too many clients", False)):
            crowd = [c for c in self.clients.values() if c.peer == conn.peer or not mine]
            if len(crowd) < limit:
                continue
            victim = max(crowd, key=lambda c: c.stalled_s(now))
            if victim.stalled_s(now) < lim.stall_s:
                return f"{why} (max {limit})"
            self.evicted += 1
            self.drop(victim)
        client = StreamClient(self.served, conn)
        if pulls:
            client.idle_since = now
        self.served += 1
        self.clients[client.key] = client
        return client

    def leave(self, client: StreamClient) -> None:
        """Free ``client``'s slot (at once; twice is harmless)."""
        if self.clients.pop(client.key, None) is not None:
            self.dropped_total += client.dropped

    def drop(self, client: StreamClient) -> None:
        """Free the slot and close the connection now, unsent data and all."""
        self.leave(client)
        client.evict()
        client.conn.abort()

    def offer(self, item: Any) -> None:
        """Give ``item`` to every client."""
        for c in self.clients.values():
            c.offer(item)

    def sweep(self) -> None:
        """Close the clients whose write has waited longer than ``send_timeout_s``."""
        now = self.clock()
        for c in self:
            if c.stalled_s(now) > self.limits.send_timeout_s:
                self.send_timeouts += 1
                self.drop(c)

    def to_json(self) -> dict[str, Any]:
        now = self.clock()
        return {str(k): c.to_json(now) for k, c in self.clients.items()}
