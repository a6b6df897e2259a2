"""MJPEG over HTTP: the emulated camera as a network camera that ``cv2.VideoCapture(url)`` opens unchanged.

``GET /stream.mjpg`` (also ``/``) answers ``multipart/x-mixed-replace`` with one JPEG part per frame; each
part carries the frame's ``X-Sequence``, ``X-Timestamp-Ns`` (start of exposure, device clock),
``X-Line-Time-Ns``, ``X-Exposure-Ns``, ``X-Readout`` and ``X-Shutter`` headers, and with an in-sensor network
``X-Insensor``: the results the frame carries as one line of JSON (``InSensorResult.to_json()`` each, a list;
each names its own source frame in ``seq``; at most ``HEADER_DETECTIONS`` detections each, ``truncated`` counting
the rest, which ``/insensor.jsonl`` has). The body is not chunked: it ends when the connection does.
``GET /snapshot.jpg`` returns the next frame, ``GET /status.json`` the server's counters (and the stream's
ledger), ``GET /imu.jsonl`` the IMU's samples as JSON lines (emu/http/imu.py), ``GET /insensor.jsonl`` the
in-sensor results as JSON lines (emu/http/insensor.py). In metadata-only mode (``insensor_output=meta``) no
image leaves the camera: the stream and snapshot answer 404 and ``/insensor.jsonl`` is what there is.
One thread encodes each frame once; the event loop (emu/http/server.py, aiohttp) writes
the same bytes to every client. Slots are fair (emu/http/slots.py): a client reading slower than the frame
rate skips frames (counted) and never grows memory, and one that does not read at all yields its slot to a
newcomer. Bad requests get an HTTP error; the server keeps serving the others. A fault plan (``faults``)
drops, holds and cuts stream parts (emu/http/faults.py); ``fault_stats`` counts what it injected.
"""

from __future__ import annotations

import asyncio
import dataclasses
import json
import socket
import threading
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any

from aiohttp import web
from rollcam.common.errors import DeviceError
from rollcam.common.faults import FaultInjector, FaultPlan
from rollcam.common.lifecycle import Closeable, Stats, Worker
from rollcam.firmware.camera import FirmwareCamera, FramePlan
from rollcam.firmware.labfaults import FrameFaults
from rollcam.sim.codecs import JPEG_QUALITY, Levels, jpeg_quality, transcode
from rollcam.sim.frame import Frame

from ..pump import FramePump
from .faults import StreamFaults
from .imu import ImuStreams
from .insensor import InSensorStreams
from .jsonl import jsonl_limits
from .server import Connection, HttpHost, HttpLimits
from .slots import StreamSlots

BOUNDARY = "rollcamframe"
STREAM_PATHS = ("/", "/stream", "/stream.mjpg", "/video", "/video.mjpg")
SNAPSHOT_WAIT_S = 5.0
SWEEP_S = 0.5  # how often streams stalled past the send timeout are looked for


@dataclass(frozen=True)
class Part:
    """One encoded frame with the headers that describe it, and its multipart chunk (built once, sent to all)."""

    sequence: int
    jpeg: bytes
    headers: tuple[tuple[str, str], ...]
    chunk: bytes = dataclasses.field(default=b"", repr=False)
    final: bool = False  # the stream ends after this part (an injected cut or disconnect)

    def __post_init__(self) -> None:
        if not self.chunk:
            object.__setattr__(self, "chunk", self.encode())

    @classmethod
    def of(cls, frame: Frame, jpeg: bytes) -> Part:
        """The part for ``frame`` encoded as ``jpeg``."""
        headers = [("X-Sequence", str(frame.sequence)), ("X-Timestamp-Ns", str(frame.timestamp_ns)),
                   ("X-Line-Time-Ns", str(frame.line_time_ns)), ("X-Exposure-Ns", str(frame.exposure_ns)),
                   ("X-Readout", frame.readout.value), ("X-Shutter", frame.shutter)]
        if frame.insensor is not None:  # compact JSON holds no CR or LF, so it is one header line
            headers.append(("X-Insensor", json.dumps([_header_result(r) for r in frame.insensor],
                                                     separators=(",", ":"))))
        return cls(frame.sequence, jpeg, tuple(headers))

    def encode(self) -> bytes:
        """The multipart chunk: boundary, headers, JPEG."""
        head = [f"--{BOUNDARY}", "Content-Type: image/jpeg", f"Content-Length: {len(self.jpeg)}"]
        head += [f"{k}: {v}" for k, v in self.headers]
        return ("\r\n".join(head) + "\r\n\r\n").encode() + self.jpeg + b"\r\n"


HEADER_DETECTIONS = 50
"""Most detections of one result in an ``X-Insensor`` header (best first; clients cap header lines near 8 kB)."""


def images_sent(camera: Any) -> bool:
    """False for a camera in metadata-only mode (``insensor_output=meta``): no image leaves the sensor."""
    cfg = getattr(getattr(camera, "spec", None), "insensor", None)
    return cfg is None or cfg.image_sent


def _header_result(result: Any) -> dict[str, Any]:
    """A result's JSON for the part header: at most ``HEADER_DETECTIONS`` detections, ``truncated`` the rest."""
    doc = result.to_json()
    extra = len(doc["detections"]) - HEADER_DETECTIONS
    if extra > 0:
        doc["detections"], doc["truncated"] = doc["detections"][:HEADER_DETECTIONS], extra
    return doc


class _Latest:
    """The newest frame waiting for the encoder (a newer one replaces it): a one-slot handoff between threads."""

    def __init__(self) -> None:
        self.cond = threading.Condition()
        self.frame: Frame | None = None
        self.closed = False

    def put(self, frame: Frame) -> None:
        with self.cond:
            self.frame = frame
            self.cond.notify_all()

    def get(self, timeout_s: float) -> Frame | None:
        with self.cond:
            if self.frame is None and not self.closed:
                self.cond.wait(timeout_s)
            frame, self.frame = self.frame, None
            return frame

    def close(self) -> None:
        with self.cond:
            self.closed = True
            self.cond.notify_all()


@dataclass
class ServerStats(Stats):
    """What the MJPEG server did: frames encoded, clients served, parts dropped for slow clients, bad requests,
    streams evicted (stalled, for a newcomer) and closed (stalled past the send timeout)."""

    frames_encoded: int = 0
    clients_served: int = 0
    dropped_total: int = 0
    bad_requests: int = 0
    evicted_stalled: int = 0
    send_timeouts: int = 0
    encode_ms_max: float = 0.0  # the slowest JPEG encode so far (one per frame, shared by every client)
    encode_ms_total: float = 0.0


class _MultipartResponse(web.StreamResponse):
    """A response whose body ends with the connection: no chunked framing around the parts (aiohttp's own
    WebSocket response turns the same length check off)."""

    _length_check = False


class MjpegServer(Closeable):
    """An HTTP server streaming one camera as MJPEG to many clients, fairly; a context manager (``with``
    starts it). ``max_clients`` is ``limits.max_streams``."""

    def __init__(self, camera: FirmwareCamera, host: str = "127.0.0.1", port: int = 0, *,
                 pump: FramePump | None = None, quality: int = JPEG_QUALITY, max_clients: int | None = None,
                 limits: HttpLimits | None = None, faults: FaultPlan | str | None = None) -> None:
        self.camera = camera
        self.quality = jpeg_quality(quality)  # refused here, not in the encoder thread
        limits = limits or HttpLimits()
        if max_clients is not None:
            limits = dataclasses.replace(limits, max_streams=max_clients)
        self.limits = limits
        self.max_clients = limits.max_streams
        self._own_pump = pump is None
        self.pump = pump or FramePump(camera, bands=1, name="rollcam-http-pump")
        self.stats = ServerStats()
        self._latest = _Latest()
        self._snapshots: set[asyncio.Future[Part]] = set()
        app = web.Application(middlewares=[self._count_errors])
        for path in STREAM_PATHS:
            app.router.add_get(path, self._stream, allow_head=False)
        app.router.add_get("/snapshot.jpg", self._snapshot, allow_head=False)
        app.router.add_get("/status.json", self._status, allow_head=False)
        app.cleanup_ctx.append(self._sweeper)
        self.http = HttpHost(app, host, port, limits=limits, name="rollcam-http")
        self.slots = StreamSlots(limits, self.http.loop.time)
        self.imu = ImuStreams(camera, StreamSlots(jsonl_limits(limits), self.http.loop.time))  # GET /imu.jsonl
        self.imu.add_to(app)
        self.insensor = InSensorStreams(camera, StreamSlots(jsonl_limits(limits), self.http.loop.time))
        self.insensor.add_to(app)
        injector = FaultInjector(FaultPlan.of(faults))
        self.fault_stats = injector.stats
        self._faults = StreamFaults(injector, self.slots.offer, self.http.loop, Part)
        self._frame_faults = FrameFaults(injector, camera)  # image faults and register resets, on the encoder thread
        self._encoder = Worker(self._encode_loop, name="rollcam-http-jpeg", wrap=DeviceError)

    @property
    def clients(self) -> dict[int, Any]:
        """The streams being served, by key."""
        return dict(self.slots.clients)

    @property
    def address(self) -> tuple[str, int]:
        """Bound host and port."""
        return self.http.address

    @property
    def url(self) -> str:
        """The stream URL clients open."""
        return f"{self.http.base_url}/stream.mjpg"

    def start(self) -> None:
        """Start serving (and streaming the camera)."""
        self._check_open()
        self.http.start()
        self.pump.add_sink(self)
        self._encoder.start()
        self.camera.stream_on()
        self.pump.start()

    _on_enter = start

    def check(self) -> None:
        """Raise (as a DeviceError) what stopped the server's loop or encoder thread, if anything did."""
        self.http.check()
        self._encoder.check()

    def _close(self) -> None:
        """Stop serving, disconnect clients, free the port; re-raises what stopped a thread early, if anything."""
        self._encoder.stop()
        self.pump.remove_sink(self)
        try:
            if self._own_pump:
                self.pump.close()
        finally:
            self._latest.close()
            try:
                self.http.close()
            finally:
                self._encoder.close()

    # --------------------------------------------------------------------------------- pump sink, encoder
    def on_band(self, frame: Frame, plan: FramePlan, band: int, n_bands: int) -> None:
        """Bands are not sent separately over HTTP."""

    def on_frame(self, frame: Frame, plan: FramePlan) -> None:
        """A frame is complete: hand it to the encoder (only the newest waits) when anyone is watching."""
        if (len(self.slots) or self._snapshots) and frame.data.size:  # metadata-only frames have no image
            self._latest.put(frame)

    def _encode_loop(self) -> None:
        levels = Levels.of_sensor(self.camera.sensor)
        while not self._encoder.stopping:
            f = self._latest.get(0.2)
            if f is None:
                continue
            f = self._frame_faults.apply(f, f.sequence)
            t0 = time.perf_counter_ns()
            part = Part.of(f, transcode(f, "MJPG", levels, self.quality).tobytes())
            ms = (time.perf_counter_ns() - t0) / 1e6
            self.stats.encode_ms_max = max(self.stats.encode_ms_max, round(ms, 3))
            self.stats.encode_ms_total += ms
            self.stats.frames_encoded += 1
            self.http.call_soon(self._publish, part)

    def _publish(self, part: Part) -> None:
        self._faults.publish(part)
        for fut in self._snapshots:
            if not fut.done():
                fut.set_result(part)
        self._snapshots.clear()

    # --------------------------------------------------------------------------------- handlers (event loop)
    @web.middleware
    async def _count_errors(self, request: web.Request, handler: Any) -> web.StreamResponse:
        try:
            return await handler(request)
        except web.HTTPException as exc:
            self.stats.bad_requests += exc.status >= 400
            raise

    async def _sweeper(self, app: web.Application) -> AsyncIterator[None]:
        async def sweep() -> None:
            while True:
                await asyncio.sleep(SWEEP_S)
                for slots in (self.slots, self.imu.slots, self.insensor.slots):
                    slots.sweep()

        task = asyncio.get_running_loop().create_task(sweep())
        yield
        task.cancel()

    def status(self) -> dict[str, Any]:
        """Counters: frames encoded, clients now and served, per-client sent and dropped parts; connections."""
        s = self.slots
        self.stats.clients_served, self.stats.dropped_total = s.served, s.dropped_total
        self.stats.evicted_stalled, self.stats.send_timeouts = s.evicted, s.send_timeouts
        doc = self.stats.to_json()
        doc["bad_requests"] += self.http.stats.malformed_requests
        return {**doc, "clients": s.to_json(), "http": self.http.stats.to_json(),
                "pump": self.pump.stats.to_json(), "camera": self.camera.stats.to_json(),
                "faults": self.fault_stats.to_json(), "jsonl": {e.path: e.status() for e in (self.imu, self.insensor)},
                **self._ledger()}

    def _ledger(self) -> dict[str, Any]:
        """The device's energy and bandwidth ledger (a host source behind ``rollcam view`` has none)."""
        stage = getattr(self.camera, "insensor", None)
        return {} if stage is None else {"ledger": stage.ledger(self.camera.spec).to_json()}

    async def _status(self, request: web.Request) -> web.Response:
        return web.Response(body=json.dumps(self.status()).encode(), content_type="application/json",
                            headers={"Cache-Control": "no-store"})

    def _image_sent(self) -> None:
        """HTTP 404 in metadata-only mode: no image leaves the sensor."""
        if not images_sent(self.camera):
            raise web.HTTPNotFound(text="metadata-only mode (insensor_output=meta): no image leaves the sensor; "
                                        "GET /insensor.jsonl for its results")

    async def _snapshot(self, request: web.Request) -> web.Response:
        self._image_sent()
        fut: asyncio.Future[Part] = asyncio.get_running_loop().create_future()
        self._snapshots.add(fut)
        try:
            part = await asyncio.wait_for(fut, SNAPSHOT_WAIT_S)
        except asyncio.TimeoutError:
            raise web.HTTPServiceUnavailable(text="the camera is not streaming") from None
        finally:
            self._snapshots.discard(fut)
        return web.Response(body=part.jpeg, content_type="image/jpeg", headers={"Cache-Control": "no-store"})

    async def _stream(self, request: web.Request) -> web.StreamResponse:
        self._image_sent()
        conn = Connection.of(request)
        if conn is None:  # gone before its turn
            raise web.HTTPServiceUnavailable(text="the connection closed")
        client = await self.slots.admit(conn)
        if isinstance(client, str):
            raise web.HTTPServiceUnavailable(text=client, headers={"Retry-After": "1"})
        resp: web.StreamResponse = web.Response(status=499)  # what aiohttp gets if the client is gone
        try:
            conn.streaming = True
            if conn.eof:  # the client left before its stream began
                return resp
            resp = _MultipartResponse(headers={
                "Content-Type": f"multipart/x-mixed-replace; boundary={BOUNDARY}",
                "Cache-Control": "no-store", "Connection": "close"})
            resp.force_close()
            sock = request.transport.get_extra_info("socket") if request.transport is not None else None
            if sock is not None:  # a fixed buffer: a reader that stops reading stalls within about a frame
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, self.limits.stream_sndbuf_bytes)
            await resp.prepare(request)
            while (part := await client.next()) is not None:
                await client.send(resp.write, part.chunk, self.http.loop.time)
                if part.final:
                    break
            return resp
        except (ConnectionError, RuntimeError):  # the client went away mid-write
            return resp
        finally:
            self.slots.leave(client)
