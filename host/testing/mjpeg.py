"""A small MJPEG-over-HTTP server for tests: serves Frames (or images) as multipart/x-mixed-replace.

It is the counterpart of the ``http://`` source for tests that need a stream without the full device
emulator: each part carries the rollcam timing headers (``X-Sequence``, ``X-Timestamp-Ns``,
``X-Exposure-Ns``, ``X-Line-Time-Ns``, ``X-Readout``, ``X-Shutter``) unless ``timing_headers=False``.
Every client gets the whole sequence from the start; the server runs in a thread, binds 127.0.0.1 on a
free port, and ``close()`` (or leaving the ``with`` block) shuts it down and releases the port.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np
from rollcam.common.lifecycle import Closeable, Worker
from rollcam.sim.codecs import JPEG_QUALITY, codec
from rollcam.sim.frame import Frame

BOUNDARY = "rollcamframe"


def jpeg_bytes(image: np.ndarray, quality: int = JPEG_QUALITY) -> bytes:
    """``image`` (BGR or grey) as JPEG bytes (the codec table's MJPG row)."""
    return codec("MJPG").encode(image, quality=quality).tobytes()


def frame_headers(frame: Frame) -> dict[str, str]:
    """The rollcam part headers of ``frame``."""
    return {"X-Sequence": str(frame.sequence), "X-Timestamp-Ns": str(frame.timestamp_ns),
            "X-Exposure-Ns": str(frame.exposure_ns), "X-Line-Time-Ns": str(frame.line_time_ns),
            "X-Readout": frame.readout.value, "X-Shutter": frame.shutter}


class MjpegTestServer(Closeable):
    """Serves ``frames`` (Frames or bare images) at ``url`` as an MJPEG stream, then ends the response."""

    def __init__(self, frames: Iterable[Frame | np.ndarray], *, path: str = "/stream.mjpg",
                 timing_headers: bool = True, content_length: bool = True, quality: int = JPEG_QUALITY) -> None:
        parts: list[tuple[dict[str, str], bytes]] = []
        for f in frames:
            image = f.data if isinstance(f, Frame) else np.asarray(f)
            headers = frame_headers(f) if isinstance(f, Frame) and timing_headers else {}
            parts.append((headers, jpeg_bytes(image, quality)))
        self.parts: Sequence[tuple[dict[str, str], bytes]] = parts
        self.path = path
        handler = _handler(self.parts, path, content_length)
        self._server = ThreadingHTTPServer(("127.0.0.1", 0), handler)
        self._server.daemon_threads = True
        self._worker = Worker(self._server.serve_forever, name="mjpeg-test-server").start()

    @property
    def url(self) -> str:
        """The stream's URL."""
        host, port = self._server.server_address[:2]
        return f"http://{host}:{port}{self.path}"

    def _close(self) -> None:
        """Stop serving and release the port."""
        self._server.shutdown()
        self._server.server_close()
        self._worker.close()


def _handler(parts: Sequence[tuple[dict[str, str], bytes]], path: str,
             content_length: bool) -> Callable[..., BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            if self.path.split("?")[0] != path:
                self.send_error(404, f"no stream at {self.path}; try {path}")
                return
            self.send_response(200)
            self.send_header("Content-Type", f"multipart/x-mixed-replace; boundary={BOUNDARY}")
            self.send_header("Cache-Control", "no-cache")
            self.send_header("Connection", "close")
            self.end_headers()
            try:
                for headers, body in parts:
                    head = [f"--{BOUNDARY}", "Content-Type: image/jpeg"]
                    if content_length:
                        head.append(f"Content-Length: {len(body)}")
                    head += [f"{k}: {v}" for k, v in headers.items()]
                    self.wfile.write(("\r\n".join(head) + "\r\n\r\n").encode("latin-1") + body + b"\r\n")
                self.wfile.write(f"--{BOUNDARY}--\r\n".encode("latin-1"))
                self.wfile.flush()
            except (BrokenPipeError, ConnectionResetError):
                pass  # the client went away; the server keeps serving others

        def log_message(self, format: str, *args: object) -> None:  # keep test output clean
            pass

    return Handler
