"""A stream client's mailbox: the two newest parts not yet sent, oldest first; a third drops the older."""

from __future__ import annotations

import asyncio
from types import SimpleNamespace

from rollcam.emu.http.slots import StreamClient


def _drain(c: StreamClient, n: int) -> list:
    async def take() -> list:
        return [await c.next() for _ in range(n)]
    return asyncio.run(take())


def test_a_client_that_keeps_up_rides_out_two_parts_at_once():
    c = StreamClient(0, SimpleNamespace(peer="127.0.0.1"))
    c.offer("a")
    c.offer("b")  # published back to back before the client's task ran: both are sent
    assert _drain(c, 2) == ["a", "b"] and c.dropped == 0


def test_a_slow_client_skips_the_oldest_and_never_queues_more_than_two():
    c = StreamClient(0, SimpleNamespace(peer="127.0.0.1"))
    for part in "abcde":
        c.offer(part)
    assert c.dropped == 3
    assert _drain(c, 2) == ["d", "e"]
    assert c.item is None and c.older is None
