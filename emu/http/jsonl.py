"""One bounded JSON-lines endpoint of the emulated camera, streamed as the device clock makes its items.

``JsonLinesStreams`` is the mechanism ``/imu.jsonl`` (emu/http/imu.py) and ``/insensor.jsonl``
(emu/http/insensor.py) share: a first line saying what the stream is, then one JSON object per item as the device
makes it, polled every ``poll_s``; ``?N`` items at most when the client asks (the subclass names the option), and
a source that stops (an IMU or network turned off, a reader fallen behind the device's buffer) ending the stream
with an ``{"error": ...}`` line. Readers hold slots as MJPEG streams do (emu/http/slots.py, one ``StreamSlots`` per
endpoint, its limits from ``jsonl_limits``): at most ``MAX_STREAMS`` per endpoint and ``MAX_STREAMS_PER_PEER`` from
one address; a reader that has been sent nothing for ``stall_s`` (one that does not read, or one waiting for a
device time far in the future) yields its slot to a newcomer, and one that has been sent nothing for
``send_timeout_s`` is closed by the server's sweep. So no reader can grow the server's memory, stall it, or
lock the others out.
"""

from __future__ import annotations

import asyncio
import dataclasses
import json
from collections.abc import Callable
from typing import Any, ClassVar

from aiohttp import web
from rollcam.common.errors import RollcamError
from rollcam.common.values import non_negative_int

from .server import Connection, HttpLimits
from .slots import StreamClient, StreamSlots

MAX_STREAMS = 8
MAX_STREAMS_PER_PEER = 4


def jsonl_limits(limits: HttpLimits) -> HttpLimits:
    """A JSON-lines endpoint's share of the server's ``limits``: at most ``MAX_STREAMS`` readers, of them at most
    ``MAX_STREAMS_PER_PEER`` from one address; the stall and timeout terms are the server's."""
    return dataclasses.replace(limits, max_streams=min(limits.max_streams, MAX_STREAMS),
                               max_streams_per_peer=min(limits.max_streams_per_peer, MAX_STREAMS_PER_PEER))


def query_option(request: web.Request, name: str, parse: Callable[[str], Any], default: Any = None) -> Any:
    """Query option ``name`` read by ``parse`` (one of rollcam.common.values' parsers), ``default`` when absent;
    HTTP 400 naming the option and what it must be when the value is bad."""
    text = request.query.get(name)
    if text is None:
        return default
    try:
        return parse(text)
    except ValueError as exc:
        raise web.HTTPBadRequest(text=f"{name}={text!r} is invalid ({exc})") from None


class JsonLinesStreams:
    """The handler of one camera's JSON-lines endpoint. A subclass sets ``path``, ``what`` (for the 503 text),
    ``limit_option`` and ``poll_s``, and says how a stream starts (``open``: its cursor, or an HTTP error when the
    camera has nothing to stream), its first line (``header``) and its next items (``take``). Readers hold
    ``slots`` (the owner sweeps them)."""

    path: ClassVar[str]
    what: ClassVar[str]
    limit_option: ClassVar[str]
    poll_s: ClassVar[float] = 0.02

    def __init__(self, camera: Any, slots: StreamSlots) -> None:
        self.camera, self.slots = camera, slots

    def add_to(self, app: web.Application) -> None:
        """Register the route on an aiohttp application."""
        app.router.add_get(self.path, self.handle, allow_head=False)

    def status(self) -> dict[str, int]:
        """Readers now and served, evicted for a newcomer, closed by the sweep (stalled or idle too long)."""
        s = self.slots
        return {"readers": len(s), "served": s.served, "evicted": s.evicted, "closed_stalled": s.send_timeouts}

    def open(self, request: web.Request) -> Any:
        """The new stream's cursor (its query options read); raises an HTTP error when there is nothing to stream."""
        raise NotImplementedError

    def header(self) -> dict[str, Any]:
        """The stream's first line."""
        raise NotImplementedError

    def take(self, cursor: Any, most: int | None) -> list[dict[str, Any]]:
        """The items made since ``cursor`` (at most ``most``), advancing it; raises ``RollcamError`` when the
        source has stopped."""
        raise NotImplementedError

    async def handle(self, request: web.Request) -> web.StreamResponse:
        """Stream items as JSON lines until the client leaves or the asked number are sent."""
        cursor = self.open(request)
        limit = query_option(request, self.limit_option, non_negative_int)
        conn = Connection.of(request)
        if conn is None:  # gone before its turn
            raise web.HTTPServiceUnavailable(text="the connection closed")
        client = await self.slots.admit(conn, pulls=True)
        if isinstance(client, str):
            raise web.HTTPServiceUnavailable(text=f"{self.what} streams: {client}", headers={"Retry-After": "1"})
        try:
            conn.streaming = True
            return await self._stream(request, client, cursor, limit)
        finally:
            self.slots.leave(client)

    async def _stream(self, request: web.Request, client: StreamClient, cursor: Any,
                      limit: int | None) -> web.StreamResponse:
        resp = web.StreamResponse(headers={"Content-Type": "application/x-ndjson", "Cache-Control": "no-store"})
        await resp.prepare(request)
        now, sent = asyncio.get_running_loop().time, 0
        try:
            await client.send(resp.write, (json.dumps(self.header()) + "\n").encode(), now)
            while not client.gone and (limit is None or sent < limit):
                try:
                    items = self.take(cursor, None if limit is None else limit - sent)
                except RollcamError as exc:  # the source stopped, or the reader fell behind it
                    await resp.write((json.dumps({"error": str(exc)}) + "\n").encode())
                    break
                if items:
                    await client.send(resp.write, "".join(json.dumps(x) + "\n" for x in items).encode(), now)
                    sent += len(items)
                else:
                    await asyncio.sleep(self.poll_s)
            if not client.gone:
                await resp.write_eof()
        except (ConnectionError, RuntimeError):  # gone, or dropped by the sweep for not reading
            pass
        return resp
