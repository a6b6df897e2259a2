"""MJPEG over HTTP: the emulated camera as a network camera that ``cv2.VideoCapture(url)`` opens unchanged.

``GET /stream.mjpg`` (also ``/``) answers ``multipart/x-mixed-replace`` with one JPEG part per frame; each
part carries the frame's ``X-Sequence``, ``X-Timestamp-Ns`` (start of exposure, device clock),
``X-Line-Time-Ns``, ``X-Exposure-Ns`` and ``X-Readout`` headers. ``GET /snapshot.jpg`` returns the next
frame, ``GET /status.json`` the server's counters. Every client has a one-part mailbox: a client reading
slower than the frame rate skips frames (counted per client and in total) and never grows memory. Bad
requests get an HTTP error; the server keeps serving the others.
"""

from __future__ import annotations

import json
import sys
import threading
from dataclasses import dataclass
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, Generic, TypeVar

from rollcam.common.errors import DeviceError
from rollcam.common.lifecycle import Closeable, Stats, Worker
from rollcam.firmware.camera import FirmwareCamera, FramePlan
from rollcam.sim.codecs import JPEG_QUALITY, Levels, jpeg_quality, transcode
from rollcam.sim.frame import Frame

from .pump import FramePump

BOUNDARY = "rollcamframe"
STREAM_PATHS = ("/", "/stream", "/stream.mjpg", "/video", "/video.mjpg")
T = TypeVar("T")


@dataclass(frozen=True)
class Part:
    """One encoded frame with the headers that describe it."""

    sequence: int
    jpeg: bytes
    headers: tuple[tuple[str, str], ...]

    def encode(self) -> bytes:
        """The multipart chunk: boundary, headers, JPEG."""
        head = [f"--{BOUNDARY}", "Content-Type: image/jpeg", f"Content-Length: {len(self.jpeg)}"]
        head += [f"{k}: {v}" for k, v in self.headers]
        return ("\r\n".join(head) + "\r\n\r\n").encode() + self.jpeg + b"\r\n"


class Mailbox(Generic[T]):
    """The newest item (a part for a client, a frame for the encoder) not yet taken; a newer item replaces
    it, and that counts as a drop."""

    def __init__(self) -> None:
        self.cond = threading.Condition()
        self.part: T | None = None
        self.closed = False
        self.sent = 0
        self.dropped = 0

    def put(self, part: T) -> None:
        with self.cond:
            if self.part is not None:
                self.dropped += 1
            self.part = part
            self.cond.notify_all()

    def get(self, timeout_s: float) -> T | None:
        with self.cond:
            if self.part is None and not self.closed:
                self.cond.wait(timeout_s)
            part, self.part = self.part, None
            return part

    def close(self) -> None:
        with self.cond:
            self.closed = True
            self.cond.notify_all()


@dataclass
class ServerStats(Stats):
    """What the HTTP server did: frames encoded, clients served, parts dropped for slow clients, bad requests."""

    frames_encoded: int = 0
    clients_served: int = 0
    dropped_total: int = 0
    bad_requests: int = 0


class MjpegServer(Closeable):
    """An HTTP server streaming one camera as MJPEG to any number of clients; a context manager (``with``
    starts it)."""

    def __init__(self, camera: FirmwareCamera, host: str = "127.0.0.1", port: int = 0, *,
                 pump: FramePump | None = None, quality: int = JPEG_QUALITY, max_clients: int = 32) -> None:
        self.camera = camera
        self.quality = jpeg_quality(quality)  # refused here, not in the encoder thread
        self.max_clients = max_clients
        self._own_pump = pump is None
        self.pump = pump or FramePump(camera, bands=1, name="rollcam-http-pump")
        self.clients: dict[int, Mailbox[Part]] = {}
        self._lock = threading.Lock()
        self._latest: Mailbox[Frame] = Mailbox()  # the frame waiting for the encoder (newest only)
        self.stats = ServerStats()
        self.httpd = _Server((host, port), _handler_class(self))
        self._encoder = Worker(self._encode_loop, name="rollcam-http-jpeg", wrap=DeviceError)
        self._stop = self._encoder.stop_event
        self._workers = (Worker(self.httpd.serve_forever, name="rollcam-http", wrap=DeviceError), self._encoder)

    @property
    def address(self) -> tuple[str, int]:
        """Bound host and port."""
        host, port = self.httpd.server_address[:2]
        return str(host), int(port)

    @property
    def url(self) -> str:
        """The stream URL clients open."""
        host, port = self.address
        return f"http://{host}:{port}/stream.mjpg"

    def start(self) -> None:
        """Start serving (and streaming the camera)."""
        self._check_open()
        self.pump.add_sink(self)
        for w in self._workers:
            w.start()
        self.camera.stream_on()
        self.pump.start()

    _on_enter = start

    def _close(self) -> None:
        """Stop serving, disconnect clients, free the port; re-raises what stopped a thread early, if anything."""
        self._encoder.stop()
        self.pump.remove_sink(self)
        try:
            if self._own_pump:
                self.pump.close()
        finally:
            self._latest.close()
            with self._lock:
                for box in self.clients.values():
                    box.close()
            if self._workers[0].alive:
                self.httpd.shutdown()
            self.httpd.server_close()
            for w in self._workers:
                w.close()

    # --------------------------------------------------------------------------------- pump sink, encoder
    def on_band(self, frame: Frame, plan: FramePlan, band: int, n_bands: int) -> None:
        """Bands are not sent separately over HTTP."""

    def on_frame(self, frame: Frame, plan: FramePlan) -> None:
        """A frame is complete: hand it to the encoder (only the newest waits)."""
        if self.clients:  # nobody watching: nothing to encode
            self._latest.put(frame)

    def _encode_loop(self) -> None:
        while not self._stop.is_set():
            f = self._latest.get(0.2)
            if f is None:
                continue
            jpeg = transcode(f, "MJPG", Levels.of_sensor(self.camera.sensor), self.quality).tobytes()
            part = Part(f.sequence, jpeg, (
                ("X-Sequence", str(f.sequence)), ("X-Timestamp-Ns", str(f.timestamp_ns)),
                ("X-Line-Time-Ns", str(f.line_time_ns)), ("X-Exposure-Ns", str(f.exposure_ns)),
                ("X-Readout", f.readout.value), ("X-Shutter", f.shutter)))
            self.stats.frames_encoded += 1
            with self._lock:
                boxes = list(self.clients.values())
            for box in boxes:
                box.put(part)

    def status(self) -> dict[str, Any]:
        """Counters: frames encoded, clients now and served, per-client sent and dropped parts."""
        with self._lock:
            clients = {str(k): {"sent": b.sent, "dropped": b.dropped} for k, b in self.clients.items()}
        return {**self.stats.to_json(), "clients": clients, "pump": self.pump.stats.to_json(),
                "camera": self.camera.stats.to_json()}

    def _join(self) -> tuple[int, Mailbox[Part]] | None:
        with self._lock:
            if len(self.clients) >= self.max_clients:
                return None
            key = self.stats.clients_served
            self.stats.clients_served += 1
            box = self.clients[key] = Mailbox()
            return key, box

    def _leave(self, key: int) -> None:
        with self._lock:
            box = self.clients.pop(key, None)
            if box is not None:
                self.stats.dropped_total += box.dropped


class _Server(ThreadingHTTPServer):
    """A threading HTTP server that treats a client vanishing mid-reply as routine, not as a traceback."""

    daemon_threads = True

    def handle_error(self, request: Any, client_address: Any) -> None:
        exc = sys.exc_info()[1]
        if not isinstance(exc, OSError):
            super().handle_error(request, client_address)


def _handler_class(server: MjpegServer) -> type[BaseHTTPRequestHandler]:
    class Handler(_Handler):
        owner = server

    return Handler


class _Handler(BaseHTTPRequestHandler):
    """One HTTP connection; ``owner`` is the MjpegServer."""

    owner: MjpegServer
    server_version = "rollcam-mjpeg/1.0"
    default_request_version = "HTTP/1.0"  # error replies to unparsable request lines still get a status line
    timeout = 10  # seconds a silent or stalled peer may hold a connection

    def log_message(self, format: str, *args: Any) -> None:
        """Quiet: the server reports through ``status()``."""

    def send_error(self, code: int, message: str | None = None, explain: str | None = None) -> None:
        """Count every error reply (malformed request lines and headers included)."""
        self.owner.stats.bad_requests += 1
        super().send_error(code, message, explain)

    def do_GET(self) -> None:
        path = self.path.split("?", 1)[0]
        if path in STREAM_PATHS:
            self._stream()
        elif path == "/snapshot.jpg":
            self._snapshot()
        elif path == "/status.json":
            self._reply(HTTPStatus.OK, "application/json", json.dumps(self.owner.status()).encode())
        else:
            self.send_error(HTTPStatus.NOT_FOUND, f"no resource {path!r}; try {STREAM_PATHS[2]}")

    def do_HEAD(self) -> None:
        self.send_error(HTTPStatus.METHOD_NOT_ALLOWED, "HEAD is not served; use GET")

    def do_POST(self) -> None:
        self.send_error(HTTPStatus.METHOD_NOT_ALLOWED, "the camera is read-only over HTTP; use GET")

    do_PUT = do_DELETE = do_PATCH = do_POST

    def _reply(self, status: int, ctype: str, body: bytes) -> None:
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def _snapshot(self) -> None:
        joined = self.owner._join()
        if joined is None:
            self.send_error(HTTPStatus.SERVICE_UNAVAILABLE, "too many clients")
            return
        key, box = joined
        try:
            part = box.get(5.0)
            if part is None:
                self.send_error(HTTPStatus.SERVICE_UNAVAILABLE, "the camera is not streaming")
                return
            self._reply(HTTPStatus.OK, "image/jpeg", part.jpeg)
        finally:
            self.owner._leave(key)

    def _stream(self) -> None:
        joined = self.owner._join()
        if joined is None:
            self.send_error(HTTPStatus.SERVICE_UNAVAILABLE, f"too many clients (max {self.owner.max_clients})")
            return
        key, box = joined
        self.close_connection = True
        try:
            self.send_response(HTTPStatus.OK)
            self.send_header("Content-Type", f"multipart/x-mixed-replace; boundary={BOUNDARY}")
            self.send_header("Cache-Control", "no-store")
            self.send_header("Connection", "close")
            self.end_headers()
            while not box.closed:
                part = box.get(0.5)
                if part is None:
                    continue
                self.wfile.write(part.encode())
                self.wfile.flush()
                box.sent += 1
        except (OSError, ValueError):
            pass  # the client went away (reset, timeout, closed socket): its frames end here
        finally:
            self.owner._leave(key)
