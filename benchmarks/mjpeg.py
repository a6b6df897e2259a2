"""MJPEG serving: ``rollcam bench mjpeg``.

- ``encode``: the server's encode of one 1080p frame (``transcode(frame, "MJPG")``: libjpeg-turbo through
  OpenCV, baseline, 4:2:0, quality ``JPEG_QUALITY``), median and 95th percentile over street frames, with
  the other chroma subsamplings and a progressive encode beside it for comparison. One encode per frame is
  shared by every client (the server's encoder thread builds one multipart chunk and every stream writes
  that same bytes object).
- ``clients``: an ``MjpegServer`` on an imx219 1080p30 street stream (BGR3: the clean render) in a process
  of its own, and ``clients`` readers from 127.0.0.1 that read as fast as they can for ``seconds``. Per
  client: parts received, gaps in the sequence numbers, and the server's own count of parts it replaced for
  that client before it was sent (``dropped``: the drops a client that keeps up must not see). Gaps that
  every client shares are frames the server never encoded (its camera skipped them or the encoder was busy),
  reported as ``server_skipped``.

Targets: encode median <= 10 ms at 1920x1080; 0 parts dropped for every client (all of them keep up).
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import statistics
import subprocess
import sys
import time
import urllib.request
from typing import Any

import numpy as np
from rollcam.common.lifecycle import Deadline, Worker

from .http_attacks import read_part, stop

TARGET_ENCODE_MS = 10.0

SERVER = """
import json, signal, sys, threading
from rollcam.emu.http.mjpeg import MjpegServer
from rollcam.firmware.camera import FirmwareCamera
w, h, fps = (int(a) for a in sys.argv[1:4])
cam = FirmwareCamera("imx219", scene={"scene": "street"}, size=(w, h), fps=fps)
cam.stream_on(); cam.render(cam.plan_next()); cam.stream_off()  # compile and build layers before serving
with MjpegServer(cam, "127.0.0.1", 0) as srv:
    print(json.dumps({"url": srv.url}), flush=True)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    stop.wait()
"""


def encode_costs(size: tuple[int, int] = (1920, 1080), frames: int = 12) -> dict[str, Any]:
    """Times of the server's JPEG encode of street frames, and of the other encoder settings beside it."""
    import cv2
    from rollcam.common.values import JPEG_QUALITY
    from rollcam.firmware.camera import FirmwareCamera
    from rollcam.sim.codecs import transcode

    cam = FirmwareCamera("imx219", scene={"scene": "street"}, size=size, fps=30)
    cam.stream_on()
    shots = [cam.render(cam.plan_next()) for _ in range(4)]
    transcode(shots[0], "MJPG")  # warm-up
    ms, size_b = [], []
    for i in range(frames):
        t = time.perf_counter()
        jpeg = transcode(shots[i % len(shots)], "MJPG")
        ms.append((time.perf_counter() - t) * 1e3)
        size_b.append(jpeg.size)
    img = shots[0].data
    options = {"444": [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444],
               "422": [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_422],
               "420": [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420],
               "420_progressive": [cv2.IMWRITE_JPEG_PROGRESSIVE, 1]}
    others = {}
    for name, extra in options.items():
        params = [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY, *extra]
        cv2.imencode(".jpg", img, params)
        t = time.perf_counter()
        for _ in range(5):
            _ok, buf = cv2.imencode(".jpg", img, params)
        others[name] = {"ms": round((time.perf_counter() - t) / 5 * 1e3, 3), "bytes": int(buf.size)}
    med = statistics.median(ms)
    return {"size": f"{size[0]}x{size[1]}", "quality": JPEG_QUALITY, "frames": frames,
            "ms_median": round(med, 3), "ms_p95": round(float(np.percentile(ms, 95)), 3),
            "bytes_median": int(statistics.median(size_b)), "opencv_jpeg": _jpeg_build(cv2), "settings": others}


def _jpeg_build(cv2: Any) -> str:
    info = cv2.getBuildInformation()
    for line in info.splitlines():
        if line.strip().startswith("JPEG:"):
            return line.split(":", 1)[1].strip()
    return "unknown"


class Reader:
    """A client reading ``/stream.mjpg`` as fast as it can (``run``, on a ``Worker``): the sequence numbers of the
    parts it got, or the connection's error."""

    def __init__(self, port: int, seconds: float) -> None:
        self.port, self.seconds = port, seconds
        self.seqs: list[int] = []
        self.error: str | None = None

    def run(self) -> None:
        """Read for ``seconds``; a connection that fails is noted in ``error`` (what else fails is raised)."""
        try:
            with socket.create_connection(("127.0.0.1", self.port), timeout=10) as s:
                s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
                s.sendall(b"GET /stream.mjpg HTTP/1.1\r\nHost: bench\r\n\r\n")
                f = s.makefile("rb", buffering=1 << 20)
                status = f.readline().decode().strip()
                if " 200 " not in status:
                    self.error = status
                    return
                while f.readline().strip():  # response headers
                    pass
                deadline = Deadline(self.seconds)
                while not deadline.expired:
                    heads, _ = read_part(f)
                    self.seqs.append(int(heads["x-sequence"]))
        except OSError as exc:
            self.error = f"{type(exc).__name__}: {exc}"


def serve_clients(clients: int = 8, seconds: float = 20.0, size: tuple[int, int] = (1920, 1080),
                  fps: int = 30) -> dict[str, Any]:
    """``clients`` readers of one server for ``seconds`` (see the module docstring)."""
    proc = subprocess.Popen([sys.executable, "-c", SERVER, str(size[0]), str(size[1]), str(fps)],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert proc.stdout is not None
        url = json.loads(proc.stdout.readline())["url"]
        port = int(url.split("//")[1].split("/")[0].rsplit(":", 1)[1])
        readers = [Reader(port, seconds) for _ in range(clients)]
        with contextlib.ExitStack() as reading:  # on the way out: every reader joined, and its error raised
            for i, r in enumerate(readers):
                reading.enter_context(Worker(r.run, name=f"mjpeg-reader-{i}", join_timeout_s=seconds + 30))
            time.sleep(seconds * 0.9)
            status = json.loads(urllib.request.urlopen(url.replace("/stream.mjpg", "/status.json"),
                                                       timeout=10).read())
    finally:
        stop(proc)
    per = status["clients"]
    seen = [set(r.seqs) for r in readers]
    anyone = set().union(*seen)
    lo = max((min(r.seqs) for r in readers if r.seqs), default=0)
    hi = min((max(r.seqs) for r in readers if r.seqs), default=-1)
    server_gaps = sum(1 for q in range(lo, hi + 1) if q not in anyone)  # no client got it: never sent
    rows = []
    for i, r in enumerate(readers):
        s = r.seqs
        gaps = int(np.sum(np.diff(s) - 1)) if len(s) > 1 else 0
        # Parts another client got and this one, within its own span, did not.
        missed = sum(1 for q in range(s[0], s[-1] + 1) if q in anyone and q not in seen[i]) if s else 0
        rows.append({"parts": len(s), "gaps": gaps, "missed_others_got": missed,
                     "dropped_by_server": per.get(str(i), {}).get("dropped"), "error": r.error})
    dropped = [row["dropped_by_server"] or 0 for row in rows]
    enc = status.get("frames_encoded", 0)
    return {"clients": clients, "seconds": seconds, "size": f"{size[0]}x{size[1]}", "fps": fps,
            "per_client": rows, "server_skipped": server_gaps, "frames_encoded": enc,
            "encode_ms_mean": round(status.get("encode_ms_total", 0.0) / max(enc, 1), 3),
            "encode_ms_max": status.get("encode_ms_max"), "camera": status.get("camera"),
            "pump": status.get("pump"), "dropped_total": int(sum(dropped)), "errors": [r.error for r in readers
                                                                                          if r.error]}


def run_mjpeg_bench(quick: bool = False) -> dict[str, Any]:
    """Both measurements and their targets; ``quick``: 640x360, 4 clients, 8 s."""
    size = (640, 360) if quick else (1920, 1080)
    enc = encode_costs(size)
    srv = serve_clients(4 if quick else 8, 8.0 if quick else 20.0, size)

    ok_clients = srv["dropped_total"] == 0 and not srv["errors"] and all(
        r["parts"] > 0 and r["missed_others_got"] == 0 for r in srv["per_client"])
    return {"encode": enc, "serve": srv,
            "targets": {"encode_ms_median": {"op": "<=", "limit": TARGET_ENCODE_MS, "value": enc["ms_median"],
                                             "pass": enc["ms_median"] <= TARGET_ENCODE_MS},
                        "client_drops": {"op": "==", "limit": 0, "value": srv["dropped_total"], "pass": ok_clients}},
            "machine": {"cpu_count": os.cpu_count(), "loadavg": list(os.getloadavg())}}


def format_mjpeg_bench(doc: dict[str, Any]) -> str:
    """The rows ``rollcam bench mjpeg`` prints."""
    e, s, t = doc["encode"], doc["serve"], doc["targets"]
    v = {True: "PASS", False: "FAIL"}
    opts = ", ".join(f"{k} {o['ms']} ms/{o['bytes'] // 1000} kB" for k, o in e["settings"].items())
    lines = [f"encode {e['size']} q{e['quality']} ({e['opencv_jpeg']}): median {e['ms_median']} ms, p95 {e['ms_p95']} "
             f"ms, {e['bytes_median'] // 1000} kB; other settings: {opts}",
             f"serve {s['clients']} clients {s['size']} {s['fps']} fps for {s['seconds']} s: {s['frames_encoded']} "
             f"frames encoded once each (mean {s['encode_ms_mean']} ms, max {s['encode_ms_max']} ms), server skipped "
             f"{s['server_skipped']}, camera {s['camera']}",
             "  per client parts/gaps/missed (others got)/dropped by server: " + ", ".join(
                 f"{r['parts']}/{r['gaps']}/{r['missed_others_got']}/{r['dropped_by_server']}"
                 for r in s["per_client"]),
             f"{v[t['encode_ms_median']['pass']]} encode median <= {TARGET_ENCODE_MS} ms; "
             f"{v[t['client_drops']['pass']]} 0 parts dropped for clients that keep up   "
             f"(loadavg {doc['machine']['loadavg']})"]
    return "\n".join(lines)
