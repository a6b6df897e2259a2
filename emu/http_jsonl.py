"""One bounded JSON-lines endpoint of the emulated camera, streamed as the device clock makes its items.

``JsonLinesStreams`` is the mechanism ``/imu.jsonl`` (emu/http_imu.py) and ``/insensor.jsonl``
(emu/http_insensor.py) share: a first line saying what the stream is, then one JSON object per item as the device
makes it, polled every ``poll_s``; ``?N`` items at most when the client asks (the subclass names the option), at
most ``MAX_STREAMS`` readers per endpoint (HTTP 503 beyond), a reader that does not read within ``SEND_TIMEOUT_S``
dropped, and a source that stops (an IMU or network turned off, a reader fallen behind the device's buffer) ending
the stream with an ``{"error": ...}`` line. So no reader can grow the server's memory or stall it.
"""

from __future__ import annotations

import asyncio
import json
from typing import Any, ClassVar

from aiohttp import web
from rollcam.common.errors import RollcamError

SEND_TIMEOUT_S = 5.0
MAX_STREAMS = 8


def query_int(request: web.Request, name: str) -> int | None:
    """Query option ``name`` as an integer >= 0, None when absent (HTTP 400 naming it when bad)."""
    text = request.query.get(name)
    if text is None:
        return None
    try:
        value = int(text)
    except ValueError:
        raise web.HTTPBadRequest(text=f"{name}={text!r} is not an integer") from None
    if value < 0:
        raise web.HTTPBadRequest(text=f"{name}={text!r} must be >= 0")
    return value


class JsonLinesStreams:
    """The handler of one camera's JSON-lines endpoint. A subclass sets ``path``, ``what`` (for the 503 text),
    ``limit_option`` and ``poll_s``, and says how a stream starts (``open``: its cursor, or an HTTP error when the
    camera has nothing to stream), its first line (``header``) and its next items (``take``)."""

    path: ClassVar[str]
    what: ClassVar[str]
    limit_option: ClassVar[str]
    poll_s: ClassVar[float] = 0.02

    def __init__(self, camera: Any) -> None:
        self.camera = camera
        self.active = 0
        self.served = 0

    def add_to(self, app: web.Application) -> None:
        """Register the route on an aiohttp application."""
        app.router.add_get(self.path, self.handle, allow_head=False)

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
        limit = query_int(request, self.limit_option)
        if self.active >= MAX_STREAMS:
            raise web.HTTPServiceUnavailable(text=f"{MAX_STREAMS} {self.what} streams already",
                                             headers={"Retry-After": "1"})
        self.active += 1
        self.served += 1
        try:
            return await self._stream(request, cursor, limit)
        finally:
            self.active -= 1

    async def _stream(self, request: web.Request, cursor: Any, limit: int | None) -> web.StreamResponse:
        resp = web.StreamResponse(headers={"Content-Type": "application/x-ndjson", "Cache-Control": "no-store"})
        await resp.prepare(request)
        sent = 0
        try:
            await asyncio.wait_for(resp.write((json.dumps(self.header()) + "\n").encode()), SEND_TIMEOUT_S)
            while limit is None or sent < limit:
                try:
                    items = self.take(cursor, None if limit is None else limit - sent)
                except RollcamError as exc:  # the source stopped, or the reader fell behind it
                    await resp.write((json.dumps({"error": str(exc)}) + "\n").encode())
                    break
                if items:
                    lines = "".join(json.dumps(x) + "\n" for x in items)
                    await asyncio.wait_for(resp.write(lines.encode()), SEND_TIMEOUT_S)
                    sent += len(items)
                else:
                    await asyncio.sleep(self.poll_s)
            await resp.write_eof()
        except (ConnectionError, RuntimeError, asyncio.TimeoutError):  # gone, or not reading
            pass
        return resp
