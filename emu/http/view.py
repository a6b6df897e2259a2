"""The live view: a page at ``/`` beside the MJPEG stream, with truth, row timing, a plot and the controls.

``LiveView`` adds to an ``MjpegServer``'s aiohttp application (before it starts): the page (``GET /`` from a
browser, that is with ``text/html`` in ``Accept``; programs asking ``/`` still get the MJPEG stream, and every
stream route stays as it was), its script and style (``/view/...``, package data in ``emu/http/web/``), a WebSocket
``/view/ws``, ``/view/state.json`` and ``/view/snapshot.json``.

One WebSocket carries everything, so picture and truth never disagree: each frame is one binary message,
``uint32 big-endian n``, ``n`` bytes of JSON (sequence, timestamp, exposure, line time, readout, row-time
ticks, ground truth, the newest detections, drops), then the JPEG the MJPEG server already encoded for its own
clients (one encode per frame, however many watch). The page draws the overlays in the browser on a canvas,
so they cost the device nothing. A page is a stream client like any other (``StreamSlots``: the same limits,
a two-part mailbox per client where a newer frame replaces the oldest unsent one, a stalled client evicted), so a
slow tab skips frames and never holds up the device or the other clients. Text messages are the controls:
``{"type": "set", "id": n, "name": "exposure_us", "value": "5000"}`` is answered ``applied`` or ``error``
(the page shows it), run one at a time off the event loop; any change of the device, from any door, is sent
to every page as a new ``state``.

Bound to a loopback address the view is open (as the stream is); bound beyond it, the page, the WebSocket and
the snapshot need ``?token=`` (made at start, printed in the banner), since the controls change the device.
A WebSocket whose ``Origin`` is another site is refused either way. Without the token, the view's routes answer
only a request whose ``Host`` names this server (``localhost``, a loopback literal, the bound address or, bound
to every address, any address literal; with the server's port): a page from ``evil.example`` whose name was
rebound to 127.0.0.1 sends ``Host: evil.example:PORT`` and is refused (403), so it can neither change the
controls nor read the state or a snapshot (DNS rebinding).
"""

from __future__ import annotations

import asyncio
import base64
import hmac
import ipaddress
import json
import secrets
import socket
import struct
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from importlib import resources
from typing import Any
from urllib.parse import urlsplit

from aiohttp import WSCloseCode, WSMsgType, web
from rollcam.common.errors import ConfigError, DeviceError
from rollcam.common.lifecycle import Closeable, Stats
from rollcam.sim.codecs import encode_image, preview_frame
from rollcam.sim.frame import Frame

from .mjpeg import MjpegServer, Part
from .server import Connection
from .slots import StreamClient
from .view_controls import ViewControls
from .view_truth import Annotate, FrameTap

AUTO = "auto"
WEB_FILES = {"index.html": "text/html", "view.js": "text/javascript", "view.css": "text/css"}
MAX_MESSAGE_BYTES = 4096  # a control message is small; aiohttp closes a WebSocket that sends more
SNAPSHOT_WAIT_S = 5.0
MAX_SNAPSHOTS = 2  # PNG encodes at once (each a full-size frame); more are answered 503


def host_names_server(host_header: str, bound: tuple[str, int]) -> bool:
    """True when a request's ``Host`` header names the server bound at ``bound`` (host, port): ``localhost``, this
    machine's name, a loopback literal or the bound address (bound to every address: any address literal), with
    the bound port. A name someone else's DNS answers for (a rebinding attack) is not this server."""
    try:
        parts = urlsplit("//" + host_header)
        name, port = (parts.hostname or "").lower(), parts.port or 80
    except ValueError:  # a port that is not a number, a bracket left open
        return False
    bound_host, bound_port = bound
    if port != bound_port or not name:
        return False
    if is_loopback(name) or name in (bound_host.lower(), socket.gethostname().lower()):
        return True
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return ipaddress.ip_address(bound_host).is_unspecified  # bound to 0.0.0.0 or ::: any of its addresses


def is_loopback(host: str) -> bool:
    """True for a loopback address (``127.0.0.0/8``, ``::1``) or ``localhost``."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


@dataclass
class ViewStats(Stats):
    """What the view did: pages connected, frame messages sent and the ns spent making them, controls."""

    pages_total: int = 0
    pages_open: int = 0
    messages: int = 0
    message_ns: int = 0
    controls_applied: int = 0
    controls_refused: int = 0
    refused_auth: int = 0
    snapshots: int = 0


class LiveView(Closeable):
    """The page and its WebSocket on ``server`` (an ``MjpegServer`` not yet started); ``close()`` detaches.

    ``controls`` is what the page may change; ``annotate`` (optional, the host's detector) boxes frames;
    ``token`` is ``AUTO`` (required when bound beyond loopback), a string, or None (never required).
    ``info()`` gives what the page shows about the source.
    """

    def __init__(self, server: MjpegServer, controls: ViewControls, *, annotate: Annotate | None = None,
                 token: str | None = AUTO, info: Callable[[], dict[str, Any]] | None = None) -> None:
        self.server, self.controls = server, controls
        host, _ = server.address
        self.token = (None if is_loopback(host) else secrets.token_urlsafe(16)) if token == AUTO else token
        self._info = info or (lambda: {})
        self.stats = ViewStats()
        self.tap = FrameTap(lambda: self.stats.pages_open > 0, annotate)
        self._files = {name: (resources.files("rollcam.emu.http") / "web" / name).read_bytes() for name in WEB_FILES}
        self._controls_pool = ThreadPoolExecutor(1, thread_name_prefix="rollcam-view-controls")
        self._snapshot_pool = ThreadPoolExecutor(MAX_SNAPSHOTS, thread_name_prefix="rollcam-view-png")
        self._snapshots = 0
        self._pages: set[_Page] = set()
        app = server.http.app
        app.middlewares.append(self._gate)
        app.router.add_get("/view", self._page, allow_head=False)
        for name in WEB_FILES:
            app.router.add_get(f"/view/{name}", self._file, allow_head=False)
        app.router.add_get("/view/ws", self._ws, allow_head=False)
        app.router.add_get("/view/state.json", self._state_json, allow_head=False)
        app.router.add_get("/view/snapshot.json", self._snapshot, allow_head=False)
        server.pump.add_sink(self.tap)

    @property
    def url(self) -> str:
        """The page's address (with the token when one is needed)."""
        return f"{self.server.http.base_url}/" + (f"?token={self.token}" if self.token else "")

    def _close(self) -> None:
        self.server.pump.remove_sink(self.tap)
        self.tap.close()
        self._controls_pool.shutdown(wait=False, cancel_futures=True)
        self._snapshot_pool.shutdown(wait=False, cancel_futures=True)

    def state(self) -> dict[str, Any]:
        """What every page is told when it connects and after any change: controls, source, counters."""
        return {"type": "state", "controls": self.controls.describe(), "source": self._info(),
                "view": self.stats.to_json(), "tap": self.tap.stats.to_json(),
                "detector": self.tap.annotate is not None}

    # ----------------------------------------------------------------------------------- gate and files
    @web.middleware
    async def _gate(self, request: web.Request, handler: Callable[..., Any]) -> web.StreamResponse:
        """The page for a browser asking ``/``; the token for the view's routes when one is needed."""
        page = request.path == "/" and request.method == "GET" and "text/html" in request.headers.get("Accept", "")
        public = request.path.removeprefix("/view/") in WEB_FILES  # the script and style are no secret
        if public or not (page or request.path == "/view" or request.path.startswith("/view/")):
            return await handler(request)
        has_token = self.token is not None and hmac.compare_digest(request.query.get("token", ""), self.token)
        if self.token is not None and not has_token:
            self.stats.refused_auth += 1
            raise web.HTTPUnauthorized(text="rollcam: this live view needs the token printed when the server "
                                            "started (open /?token=...)\n")
        if not has_token and not host_names_server(request.headers.get("Host", ""), self.server.address):
            self.stats.refused_auth += 1  # DNS rebinding: another site's name resolved to this server
            raise web.HTTPForbidden(text=f"rollcam: Host {request.headers.get('Host', '')[:80]!r} does not name "
                                         "this server (open it by its address or localhost)\n")
        return await (self._page(request) if page else handler(request))

    async def _page(self, request: web.Request) -> web.Response:
        return self._reply("index.html")

    async def _file(self, request: web.Request) -> web.Response:
        return self._reply(request.path.rsplit("/", 1)[1])

    def _reply(self, name: str) -> web.Response:
        return web.Response(body=self._files[name], content_type=WEB_FILES[name], headers={
            "Cache-Control": "no-store", "X-Content-Type-Options": "nosniff",
            "Content-Security-Policy": "default-src 'self'; img-src 'self' blob: data:; "
                                       "connect-src 'self' ws: wss:; frame-ancestors 'none'"})

    async def _state_json(self, request: web.Request) -> web.Response:
        return web.json_response(self.state(), headers={"Cache-Control": "no-store"})

    # ----------------------------------------------------------------------------------- snapshot
    async def _snapshot(self, request: web.Request) -> web.Response:
        """The next frame as PNG (base64) with its truth: one JSON the page saves as two files."""
        if self._snapshots >= MAX_SNAPSHOTS:
            raise web.HTTPServiceUnavailable(text="snapshots are busy", headers={"Retry-After": "1"})
        self._snapshots += 1
        loop = asyncio.get_running_loop()
        fut: asyncio.Future[Frame] = loop.create_future()

        def got(frame: Frame) -> None:
            self.server.http.call_soon(lambda: fut.done() or fut.set_result(frame))

        self.tap.next_frame(got)
        try:
            frame = await asyncio.wait_for(fut, SNAPSHOT_WAIT_S)
            png = await loop.run_in_executor(self._snapshot_pool, _png, frame)
        except asyncio.TimeoutError:
            raise web.HTTPServiceUnavailable(text="the camera is not streaming") from None
        finally:
            self.tap.cancel(got)
            self._snapshots -= 1
        self.stats.snapshots += 1
        info = self.tap.info(frame.sequence)
        truth = {**(info.to_json() if info is not None else {"seq": frame.sequence}),
                 "detections": self.tap.detections, "source": self._info()}
        return web.json_response({"name": f"rollcam-{frame.sequence:06d}", "truth": truth,
                                  "png_base64": base64.b64encode(png).decode()}, headers={"Cache-Control": "no-store"})

    # ----------------------------------------------------------------------------------- WebSocket
    def _same_origin(self, request: web.Request) -> bool:
        origin = request.headers.get("Origin")
        return origin is None or urlsplit(origin).netloc.lower() == request.host.lower()

    async def _ws(self, request: web.Request) -> web.StreamResponse:
        if not self._same_origin(request):
            self.stats.refused_auth += 1
            raise web.HTTPForbidden(text="WebSocket from another site refused\n")
        conn = Connection.of(request)
        if conn is None:
            raise web.HTTPServiceUnavailable(text="the connection closed")
        client = await self.server.slots.admit(conn)  # a page is a stream like any other: the same limits
        if isinstance(client, str):
            raise web.HTTPServiceUnavailable(text=client, headers={"Retry-After": "1"})
        ws = web.WebSocketResponse(max_msg_size=MAX_MESSAGE_BYTES, compress=False, autoping=True)
        page = _Page(self, ws, client)
        try:
            conn.streaming = True
            await ws.prepare(request)
            sock = request.transport.get_extra_info("socket") if request.transport is not None else None
            if sock is not None:  # as for MJPEG: a tab that stops reading stalls within about a frame
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, self.server.limits.stream_sndbuf_bytes)
            self._pages.add(page)
            self.stats.pages_total += 1
            self.stats.pages_open = len(self._pages)
            await page.run()
        except (ConnectionError, RuntimeError):  # the tab went away mid-write
            pass
        finally:
            self._pages.discard(page)
            self.stats.pages_open = len(self._pages)
            self.server.slots.leave(client)
        return ws

    async def apply(self, message: Any) -> dict[str, Any]:
        """Run one control message off the loop (one at a time); the reply the page shows."""
        mid = message.get("id") if isinstance(message, dict) else None
        try:
            if not isinstance(message, dict) or message.get("type") != "set":
                raise ConfigError(f"a control message is {{'type': 'set', 'name': ..., 'value': ...}}, "
                                  f"got {str(message)[:80]!r}")
            name, value = message.get("name"), message.get("value")
            if not isinstance(name, str) or not isinstance(value, (str, int, float, bool)):
                raise ConfigError(f"control name and value must be text, got {name!r}={value!r}")
            text = value if isinstance(value, str) else json.dumps(value)
            loop = asyncio.get_running_loop()
            done = await loop.run_in_executor(self._controls_pool, self.controls.apply, name, text)
        except (ConfigError, DeviceError) as exc:
            self.stats.controls_refused += 1
            return {"type": "error", "id": mid, "name": message.get("name") if isinstance(message, dict) else None,
                    "message": str(exc)}
        self.stats.controls_applied += 1
        return {"type": "applied", "id": mid, "name": name, "value": done}

    def frame_message(self, part: Part, client: StreamClient) -> bytes:
        """One frame's binary message: header length, JSON header, the shared JPEG."""
        info = self.tap.info(part.sequence)
        head = info.to_json() if info is not None else {"seq": part.sequence, **dict(part.headers)}
        cam = self.server.camera
        doc = {**head, "dropped": client.dropped, "skipped": cam.stats.skipped, "detections": self.tap.detections}
        data = json.dumps(doc, separators=(",", ":")).encode()
        return struct.pack(">I", len(data)) + data + part.jpeg


class _Page:
    """One connected page: frames out as they come, control messages in, a new state when the device changes."""

    def __init__(self, view: LiveView, ws: web.WebSocketResponse, client: StreamClient) -> None:
        self.view, self.ws, self.client = view, ws, client
        self.lock = asyncio.Lock()  # one message at a time on the socket: frames and replies interleave whole
        self.version: Any = None

    async def send_text(self, doc: dict[str, Any]) -> None:
        async with self.lock:
            await self.ws.send_str(json.dumps(doc))

    async def run(self) -> None:
        await self.send_state()
        sender = asyncio.get_running_loop().create_task(self.send_frames())
        try:
            async for msg in self.ws:
                if msg.type != WSMsgType.TEXT:
                    break
                try:
                    message = json.loads(msg.data)
                except ValueError:
                    message = msg.data
                await self.send_text(await self.view.apply(message))
                await self.send_state()
        finally:
            sender.cancel()
            self.client.gone = True

    async def send_state(self) -> None:
        self.version = self.view.controls.version()
        await self.send_text(self.view.state())

    async def send_frames(self) -> None:
        view, loop = self.view, asyncio.get_running_loop()
        clock = view.tap.clock
        while (part := await self.client.next()) is not None:
            if view.controls.version() is not self.version:  # changed through another door (serial, registers)
                await self.send_state()
            if not (part.final and len(part.chunk) < len(part.encode())):  # a cut frame never arrives
                t0 = clock()
                message = view.frame_message(part, self.client)
                view.stats.message_ns += clock() - t0
                view.stats.messages += 1
                async with self.lock:
                    await self.client.send(self.ws.send_bytes, message, loop.time)
            if part.final:  # an injected cut or disconnect: the camera went away, as the MJPEG streams see it
                await self.ws.close(code=WSCloseCode.GOING_AWAY, message=b"camera went away")
                return


def _png(frame: Frame) -> bytes:
    """``frame``'s 8-bit preview as PNG (lossless: the snapshot is the frame, not the stream's JPEG)."""
    return encode_image(preview_frame(frame), "png", error=DeviceError, what=f"frame {frame.sequence}")
