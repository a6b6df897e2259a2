"""The emulator's HTTP host: an aiohttp application on one event-loop thread, behind limits no client can defeat.

``HttpHost`` binds the listening socket at construction (IPv4 or IPv6, so a bad address fails there) and
serves an ``aiohttp.web.Application`` on a ``Worker`` thread running one asyncio loop: no thread per client.
Every accepted connection passes through ``Connection``, which enforces what aiohttp leaves to the deployer:

- a whole-request deadline: a request's line and headers must be complete ``request_timeout_s`` after the
  connection opened (or after the previous response), else ``408`` and close, however slowly bytes trickle in;
- a byte limit on a request's head (``max_request_bytes``: ``414`` before the first line ends, ``431`` after),
  beside aiohttp's own line, field and header-count limits;
- a bound on connections: at ``max_connections`` a new one evicts the oldest connection still waiting for
  its request (slowloris holds nothing), and only when every connection is inside a request is the new one
  answered ``503`` and closed.

At the descriptor limit asyncio stops accepting for a second and retries (no busy loop; waiting clients sit
in the ``backlog``); ``stats.accept_paused`` counts those pauses. aiohttp is Apache-2.0.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from aiohttp import web
from aiohttp.http_exceptions import HttpProcessingError
from rollcam.common.errors import DeviceError
from rollcam.common.lifecycle import Closeable, Stats, Worker

SERVER_NAME = "rollcam-mjpeg/2.0"


@dataclass(frozen=True)
class HttpLimits:
    """What one HTTP server grants its clients; small values make the attacks of the tests cheap to show."""

    max_connections: int = 256  # open connections in all (each is a descriptor)
    backlog: int = 128  # connections the kernel queues while the server is busy or out of descriptors
    request_timeout_s: float = 10.0  # request line and headers complete within this, from the connection's start
    max_request_bytes: int = 16384  # request line and headers together
    max_headers: int = 32  # header lines in one request
    max_streams: int = 32  # long-lived responses (MJPEG streams) at once
    max_streams_per_peer: int = 8  # of those, from one address
    stall_s: float = 2.0  # a stream whose write has not drained for this long yields its slot to a newcomer
    admit_wait_s: float = 5.0  # a newcomer finding every slot live waits this long for one to stall or free
    stream_sndbuf_bytes: int = 262144  # a stream's kernel send buffer (fixed, so a silent reader stalls soon)
    send_timeout_s: float = 10.0  # a stream whose write has not drained for this long is closed anyway

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not value > 0:
                raise ValueError(f"HttpLimits.{name} must be > 0, got {value!r}")


@dataclass
class HttpStats(Stats):
    """What the host did with connections: open now, accepted, refused, evicted, timed out, shed."""

    connections_open: int = 0
    connections_total: int = 0
    refused_full: int = 0  # answered 503: every connection was inside a request
    evicted_waiting: int = 0  # closed to make room: the oldest connection still without a request
    request_timeouts: int = 0  # answered 408: the request did not arrive in time
    oversized_requests: int = 0  # answered 414/431: the request's head was over max_request_bytes
    accept_paused: int = 0  # out of descriptors: accepting paused for a second
    malformed_requests: int = 0  # refused by aiohttp's parser (400)


class _ErrorLog(logging.LoggerAdapter):
    """aiohttp's error log for one host: a request its parser refused is counted, not logged with a traceback
    (a client's mistake is routine); anything else goes to the ``rollcam.emu.http`` logger."""

    def __init__(self, stats: HttpStats) -> None:
        super().__init__(logging.getLogger("rollcam.emu.http"), {})
        self.stats = stats

    def log(self, level: int, msg: object, *args: Any, **kwargs: Any) -> None:
        exc = kwargs.get("exc_info")
        if exc is True:
            exc = sys.exc_info()[1]
        if isinstance(exc, HttpProcessingError):
            self.stats.malformed_requests += 1
            return
        super().log(level, msg, *args, **kwargs)


def _reply(status: str) -> bytes:
    return f"HTTP/1.1 {status}\r\nContent-Length: 0\r\nConnection: close\r\n\r\n".encode()


class Connection(asyncio.Protocol):
    """One accepted connection: aiohttp's protocol behind the host's deadline, byte limit and admission.

    A handler finds it with ``Connection.of(request)``; the host's middleware marks when a request is being
    handled (its deadline is off then); a handler that streams marks ``streaming``, and then the client's
    end of the connection (EOF) ends the stream at once, whether or not a frame is being sent.
    """

    def __init__(self, host: HttpHost, inner: asyncio.Protocol) -> None:
        self.host, self.inner = host, inner
        self.transport: asyncio.Transport | None = None
        self.peer = ""
        self.admitted = self.in_request = self.streaming = self.eof = False
        self._inner_open = False  # aiohttp's protocol saw connection_made, so it must see connection_lost
        self._head_bytes, self._line_bytes = 0, -1  # bytes of the request's head, of its first line (-1: open)
        self._timer: asyncio.TimerHandle | None = None

    @staticmethod
    def of(request: web.BaseRequest) -> Connection | None:
        """The connection a request came on (None once it is gone)."""
        transport = request.transport
        proto = transport.get_protocol() if transport is not None else None
        return proto if isinstance(proto, Connection) else None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]
        peer = transport.get_extra_info("peername")
        self.peer = str(peer[0]) if peer else ""
        if not self.host.admit(self):
            self.refuse("503 Service Unavailable")
            return
        self.admitted = self._inner_open = True
        self.inner.connection_made(transport)
        self._arm()

    def data_received(self, data: bytes) -> None:
        if not self.admitted:
            return
        if not self.in_request:
            if self._line_bytes < 0 and (end := data.find(b"\n")) >= 0:
                self._line_bytes = self._head_bytes + end
            self._head_bytes += len(data)
            limit = self.host.limits.max_request_bytes
            if self._head_bytes > limit:
                self.host.stats.oversized_requests += 1
                long_line = self._line_bytes < 0 or self._line_bytes > limit
                self.refuse("414 URI Too Long" if long_line else "431 Request Header Fields Too Large")
                return
        self.inner.data_received(data)

    def eof_received(self) -> bool:
        """The client closed its side: a request it already sent is still answered (then the connection
        closes); otherwise, a stream or no request at all, the connection ends now."""
        self.eof = True
        pending = not self.streaming and (self.in_request or self._head_bytes > 0)
        if self.admitted:
            self.inner.eof_received()
            if pending and isinstance(self.inner, web.RequestHandler):
                self.inner.keep_alive(False)  # answer what was asked, then close
        return pending

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm()
        self.host.forget(self)
        if self._inner_open:
            self._inner_open = False
            self.inner.connection_lost(exc)

    def pause_writing(self) -> None:
        self.inner.pause_writing()

    def resume_writing(self) -> None:
        self.inner.resume_writing()

    def refuse(self, status: str) -> None:
        """Answer ``status`` (a status line's code and reason) and close, without aiohttp."""
        self.admitted = False
        self.host.stats.refused_full += status.startswith("503")
        if self.transport is not None and not self.transport.is_closing():
            self.transport.write(_reply(status))
            self.transport.close()

    def abort(self) -> None:
        """Drop the connection now, unsent data and all (a stalled reader, or to make room)."""
        if self.transport is not None:
            self.transport.abort()

    def request_started(self) -> None:
        self.in_request = True
        self._disarm()

    def request_done(self) -> None:
        """The handler returned: the next request's deadline starts."""
        self.in_request = self.streaming = False
        self._head_bytes, self._line_bytes = 0, -1
        self._arm()

    def _arm(self) -> None:
        self._disarm()
        self._timer = self.host.loop.call_later(self.host.limits.request_timeout_s, self._expired)

    def _disarm(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _expired(self) -> None:
        self._timer = None
        if not self.in_request:
            self.host.stats.request_timeouts += 1
            self.refuse("408 Request Timeout")


@web.middleware
async def _track_requests(request: web.Request, handler: Callable[..., Any]) -> web.StreamResponse:
    conn = Connection.of(request)
    if conn is not None:
        conn.request_started()
    try:
        return await handler(request)
    finally:
        if conn is not None:
            conn.request_done()


class HttpHost(Closeable):
    """An aiohttp application served on ``host:port`` from one event-loop thread, under ``limits``.

    ``app`` is built by the owner (routes, ``cleanup_ctx`` for background tasks); ``call_soon(fn, ...)`` runs
    ``fn`` on the loop from any thread (a no-op once the loop is gone).
    """

    def __init__(self, app: web.Application, host: str, port: int, *, limits: HttpLimits, name: str) -> None:
        self.limits, self.name = limits, name
        self.stats = HttpStats()
        self.app = app
        app.middlewares.append(_track_requests)
        app.on_response_prepare.append(_server_header)
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self.sock = socket.create_server((host, port), family=family, backlog=limits.backlog)
        self.sock.setblocking(False)
        self.loop: asyncio.AbstractEventLoop = asyncio.new_event_loop()
        self.connections: dict[Connection, None] = {}  # in accept order: the oldest first
        self._ready = threading.Event()
        self._stop: asyncio.Event | None = None
        self._worker = Worker(self._run, name=name, wrap=DeviceError)

    @property
    def address(self) -> tuple[str, int]:
        """Bound host and port."""
        host, port = self.sock.getsockname()[:2]
        return str(host), int(port)

    @property
    def base_url(self) -> str:
        """``http://HOST:PORT`` (an IPv6 address in brackets)."""
        host, port = self.address
        return f"http://[{host}]:{port}" if ":" in host else f"http://{host}:{port}"

    def start(self) -> None:
        """Start the loop thread and wait until it accepts connections."""
        self._check_open()
        self._worker.start()
        while not self._ready.wait(0.1):
            self._worker.check()
            if not self._worker.alive:
                raise DeviceError(f"{self.name} ended before it served")

    def check(self) -> None:
        """Raise (as a DeviceError) what stopped the loop thread, if anything did."""
        self._worker.check()

    def call_soon(self, fn: Callable[..., Any], *args: Any) -> None:
        """Run ``fn(*args)`` on the loop thread soon; nothing once the loop has stopped."""
        with contextlib.suppress(RuntimeError):  # the loop is closed: the server is going away
            self.loop.call_soon_threadsafe(fn, *args)

    def _close(self) -> None:
        try:
            if self._worker.alive:
                self.call_soon(self._request_stop)
            self._worker.close()  # re-raises what stopped the loop thread, if anything did
        finally:  # the port is freed even then
            self.sock.close()
            if not self.loop.is_running() and not self.loop.is_closed():
                self.loop.close()

    def _request_stop(self) -> None:
        if self._stop is not None:
            self._stop.set()

    def _run(self) -> None:
        asyncio.set_event_loop(self.loop)
        try:
            self.loop.run_until_complete(self._serve())
        finally:
            self.loop.run_until_complete(self.loop.shutdown_asyncgens())
            self.loop.close()

    async def _serve(self) -> None:
        self._stop = asyncio.Event()
        self.loop.set_exception_handler(self._loop_error)
        lim = self.limits
        runner = web.AppRunner(self.app, handle_signals=False, access_log=None, handler_cancellation=True,
                               logger=_ErrorLog(self.stats),
                               keepalive_timeout=2 * lim.request_timeout_s, max_headers=lim.max_headers,
                               max_line_size=lim.max_request_bytes, max_field_size=lim.max_request_bytes)
        await runner.setup()
        server = runner.server
        assert server is not None
        listener = await self.loop.create_server(lambda: Connection(self, server()), sock=self.sock,
                                                 backlog=lim.backlog)
        self._ready.set()
        try:
            await self._stop.wait()
        finally:
            listener.close()
            for conn in list(self.connections):
                conn.abort()
            await runner.cleanup()
            await listener.wait_closed()

    def admit(self, conn: Connection) -> bool:
        """Room for ``conn``: under the limit, or by evicting the oldest connection still waiting for a request."""
        if len(self.connections) >= self.limits.max_connections:
            idle = next((c for c in self.connections if not c.in_request), None)
            if idle is None:
                return False
            self.stats.evicted_waiting += 1
            self.forget(idle)
            idle.abort()
        self.connections[conn] = None
        self.stats.connections_total += 1
        self.stats.connections_open = len(self.connections)
        return True

    def forget(self, conn: Connection) -> None:
        """``conn`` is closed: it no longer holds a place (twice is harmless)."""
        self.connections.pop(conn, None)
        self.stats.connections_open = len(self.connections)

    def _loop_error(self, loop: asyncio.AbstractEventLoop, context: dict[str, Any]) -> None:
        """Out of descriptors is routine under attack (asyncio retries in a second); clients that vanish mid-
        reply are routine always; anything else is reported as asyncio would."""
        exc = context.get("exception")
        if "out of system resource" in str(context.get("message", "")):
            self.stats.accept_paused += 1
        elif not isinstance(exc, (ConnectionError, TimeoutError)):
            loop.default_exception_handler(context)


async def _server_header(request: web.Request, response: web.StreamResponse) -> None:
    response.headers["Server"] = SERVER_NAME
