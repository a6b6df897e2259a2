"""The in-sensor network's results over HTTP: ``GET /insensor.jsonl``, one JSON object per result, as they are done.

Each line is an ``InSensorResult.to_json()`` (``seq`` of the frame it came from, its row timing, ``input_ns`` and
``done_ns`` on the device clock, ``detections`` as ``{box, score, cls}``, the output ``tensor_shapes``; with
``?tensors=1`` the tensors themselves); the first line is ``{"insensor": {...}}``, the network's programming,
with the stream's energy and bandwidth ledger (``rollcam.firmware.ledger``). A result is written once the
device clock has passed its ``done_ns``. ``?from_seq=N`` starts at frame N if it is still among the last
frames kept (default: the next result), ``?results=N`` ends the response after N results (default: endless).
It works in both output modes; in metadata-only mode (``insensor_output=meta``) it is the only thing the
camera sends. Bounded as ``/imu.jsonl`` is: at most ``MAX_STREAMS`` readers (HTTP 503 beyond), a reader that
does not read within ``SEND_TIMEOUT_S`` is dropped.
"""

from __future__ import annotations

import asyncio
import json
from typing import Any

from aiohttp import web
from rollcam.firmware.camera import FirmwareCamera

from .http_imu import query_int

INSENSOR_PATH = "/insensor.jsonl"
POLL_S = 0.01
SEND_TIMEOUT_S = 5.0
MAX_STREAMS = 8


def programming(camera: FirmwareCamera) -> dict[str, Any]:
    """The first line: the in-sensor options in effect and the stream's ledger."""
    values = camera.spec.option_values()
    return {"insensor": {k: (list(v) if isinstance(v, tuple) else v) for k, v in values.items()
                         if k.startswith("insensor")}, "ledger": camera.insensor.ledger(camera.spec).to_json()}


class InSensorStreams:
    """The ``/insensor.jsonl`` handler of one camera, bounded to ``MAX_STREAMS`` readers."""

    def __init__(self, camera: FirmwareCamera) -> None:
        self.camera = camera
        self.active = 0
        self.served = 0

    def add_to(self, app: web.Application) -> None:
        """Register the route on an aiohttp application."""
        app.router.add_get(INSENSOR_PATH, self.handle, allow_head=False)

    async def handle(self, request: web.Request) -> web.StreamResponse:
        """Stream results as JSON lines until the client leaves or ``results=N`` are sent."""
        spec = getattr(self.camera, "spec", None)
        if spec is None or spec.insensor is None:
            raise web.HTTPNotFound(text="this camera has no in-sensor network (insensor=SPEC sets one)")
        limit = query_int(request, "results")
        start = query_int(request, "from_seq")
        tensors = request.query.get("tensors", "0") not in ("0", "off", "false", "")
        if self.active >= MAX_STREAMS:
            raise web.HTTPServiceUnavailable(text=f"{MAX_STREAMS} in-sensor streams already",
                                             headers={"Retry-After": "1"})
        self.active += 1
        self.served += 1
        try:
            return await self._stream(request, limit, start, tensors)
        finally:
            self.active -= 1

    async def _stream(self, request: web.Request, limit: int | None, start: int | None,
                      tensors: bool) -> web.StreamResponse:
        resp = web.StreamResponse(headers={"Content-Type": "application/x-ndjson", "Cache-Control": "no-store"})
        await resp.prepare(request)
        cam = self.camera
        if start is None:  # from the next result done after now
            done = cam.insensor.recent(cam.clock_ns())
            since = done[-1].seq + 1 if done else 0
        else:
            since = start
        sent = 0
        try:
            await asyncio.wait_for(resp.write((json.dumps(programming(cam)) + "\n").encode()), SEND_TIMEOUT_S)
            while limit is None or sent < limit:
                if cam.spec.insensor is None:
                    await resp.write((json.dumps({"error": "the in-sensor network was turned off"}) + "\n").encode())
                    break
                fresh = cam.insensor.recent(cam.clock_ns(), since)
                if limit is not None:
                    fresh = fresh[: limit - sent]
                if fresh:
                    lines = "".join(json.dumps(r.to_json(tensors=tensors)) + "\n" for r in fresh)
                    await asyncio.wait_for(resp.write(lines.encode()), SEND_TIMEOUT_S)
                    sent += len(fresh)
                    since = fresh[-1].seq + 1
                else:
                    await asyncio.sleep(POLL_S)
            await resp.write_eof()
        except (ConnectionError, RuntimeError, asyncio.TimeoutError):  # gone, or not reading
            pass
        return resp
