"""Attacks on ``rollcam emulate --http``, each measured while a normal client streams (loopback only).

Run ``python -m rollcam.benchmarks.http_attacks [--quick]``: every attack starts a fresh server process, runs
for a bounded time, and reports the server's threads, descriptors, RSS and CPU time at the attack's peak, and
what a normal client (from 127.0.0.1; attackers come from 127.0.0.2 and up) saw: the HTTP status, the time
to its first frame and the latency of its frames (arrival minus the frame's timestamp on the device
clock; reported as the delay added over the best frame of an idle viewer of the same server, measured just
before the attack, whose own median is ``idle``). The attacks are those of issue 11:

- ``lockout``: 32 stream requests from one address that never read, reconnecting every 10 s (the issue's);
- ``lockout32``: the same from 32 addresses (per-address limits do not help; eviction of stalled readers must);
- ``slowloris``: 1,000 connections sending one header byte every 5 s;
- ``burst``: 200 snapshot requests connecting at once;
- ``fdlimit``: the server under RLIMIT_NOFILE 128 while 200 trickling connections are held open for 6 s (less
  than the new request deadline), then released; CPU share of the server before and during.

This is the larger run the closing note of the issue quotes; the tests show each mechanism with small limits.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import resource
import socket
import statistics
import subprocess
import sys
import threading
import time
from typing import Any

from rollcam.common.lifecycle import Worker

CLK_TCK = os.sysconf("SC_CLK_TCK")


SERVER = """
import json, signal, threading
from rollcam.emu.http.mjpeg import MjpegServer
from rollcam.firmware.camera import FirmwareCamera
cam = FirmwareCamera("imx219", scene={"scene": "chart"}, size=(640, 480))
with MjpegServer(cam, "127.0.0.1", 0) as srv:
    print(json.dumps({"http": {"url": srv.url}}), flush=True)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    stop.wait()
"""


def serve(nofile: int | None = None) -> tuple[subprocess.Popen, str, int]:
    """A fresh emulated camera (imx219, chart, 640x480) behind ``MjpegServer`` on 127.0.0.1, port chosen by the
    system, in a process of its own (what ``rollcam emulate --http`` serves): the process, host and port."""
    def limit() -> None:
        if nofile is not None:
            resource.setrlimit(resource.RLIMIT_NOFILE, (nofile, nofile))

    proc = subprocess.Popen([sys.executable, "-c", SERVER], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                            text=True, preexec_fn=limit)
    assert proc.stdout is not None
    url = json.loads(proc.stdout.readline())["http"]["url"]
    host, port = url.split("//")[1].split("/")[0].rsplit(":", 1)
    return proc, host, int(port)


def read_part(f: Any) -> tuple[dict[str, str], bytes]:
    """The next part of a multipart MJPEG stream read from the file ``f``: its headers (lower-case) and body."""
    while not f.readline().startswith(b"--"):  # to the part's boundary
        pass
    heads = {}
    while (line := f.readline().strip()) != b"":
        k, v = line.decode().split(":", 1)
        heads[k.lower()] = v.strip()
    return heads, f.read(int(heads["content-length"]))


def stop(proc: subprocess.Popen) -> None:
    """End a server process (SIGTERM, then SIGKILL if it does not end within 10 s)."""
    proc.terminate()
    try:
        proc.wait(10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(10)


def figures(pid: int) -> dict[str, Any]:
    """Threads, open descriptors, RSS (MB) and CPU time (s) of process ``pid``."""
    with open(f"/proc/{pid}/status") as f:
        status = dict(line.split(":", 1) for line in f.read().splitlines() if ":" in line)
    with open(f"/proc/{pid}/stat") as f:
        stat = f.read().rsplit(")", 1)[1].split()
    return {"threads": int(status["Threads"]), "fds": len(os.listdir(f"/proc/{pid}/fd")),
            "rss_mb": round(int(status["VmRSS"].split()[0]) / 1024, 1),
            "cpu_s": round((int(stat[11]) + int(stat[12])) / CLK_TCK, 2)}


class Viewer:
    """A normal client from 127.0.0.1 streaming for ``seconds`` (``run`` here, or ``start`` it on a ``Worker`` and
    ``join`` it): its status line, first-frame time, latencies."""

    def __init__(self, port: int, seconds: float) -> None:
        self.port, self.seconds = port, seconds
        self.status = "no answer"
        self.first_s: float | None = None
        self.latency_ms: list[float] = []
        self._worker = Worker(self.run, name="bench-viewer")

    def start(self) -> None:
        """Stream on a thread of its own."""
        self._worker.start()

    def join(self, timeout_s: float) -> None:
        """Wait for the stream's end (at most ``timeout_s``); what failed, other than the connection, is raised."""
        self._worker.join(timeout_s)

    def run(self) -> None:
        """Stream for ``seconds``; a failed connection is noted in ``status``."""
        t0 = time.monotonic()
        try:
            with socket.create_connection(("127.0.0.1", self.port), timeout=10) as s:
                s.sendall(b"GET /stream.mjpg HTTP/1.1\r\nHost: x\r\n\r\n")
                f = s.makefile("rb")
                self.status = f.readline().decode().strip()
                if " 200 " not in self.status:
                    return
                while f.readline().strip():  # the response's headers
                    pass
                while time.monotonic() - t0 < self.seconds:
                    heads, _ = read_part(f)
                    now = time.monotonic_ns()
                    if self.first_s is None:
                        self.first_s = time.monotonic() - t0
                    self.latency_ms.append((now - int(heads["x-timestamp-ns"])) / 1e6)
        except OSError as exc:
            self.status = f"{self.status}; {type(exc).__name__}"

    def result(self, base_ms: float = 0.0) -> dict[str, Any]:
        """What the viewer saw; latencies less ``base_ms`` (the idle best of the same server)."""
        lat = sorted(x - base_ms for x in self.latency_ms)
        return {"status": self.status, "first_frame_s": None if self.first_s is None else round(self.first_s, 2),
                "frames": len(lat), "latency_ms_median": round(statistics.median(lat), 1) if lat else None,
                "latency_ms_max": round(lat[-1], 1) if lat else None}


def idle_base(port: int) -> float:
    """The best latency (ms, arrival minus device timestamp) of a viewer of an idle server, for 5 s."""
    ref = Viewer(port, 5)
    ref.run()
    return min(ref.latency_ms)


def _connect(port: int, source: str, rcvbuf: int | None = None) -> socket.socket | None:
    s = socket.socket()
    try:
        if rcvbuf:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        s.bind((source, 0))
        s.settimeout(5)
        s.connect(("127.0.0.1", port))
        return s
    except OSError:
        s.close()
        return None


def lockout(port: int, pid: int, base: float, seconds: float, addresses: int) -> dict[str, Any]:
    """32 non-reading stream clients from ``addresses`` addresses, reconnecting every 10 s; a viewer joins
    after 2 s."""
    socks: list[socket.socket] = []

    def connect_all() -> None:
        for s in socks:
            s.close()
        socks.clear()
        for i in range(32):
            s = _connect(port, f"127.0.0.{2 + i % addresses}")
            if s is not None:
                with contextlib.suppress(OSError):
                    s.sendall(b"GET /stream.mjpg HTTP/1.1\r\nHost: x\r\n\r\n")
                socks.append(s)

    connect_all()
    time.sleep(2)
    viewer = Viewer(port, seconds - 2)
    viewer.start()
    t0, peak = time.monotonic(), figures(pid)
    while time.monotonic() - t0 < seconds - 2:
        time.sleep(1)
        peak = figures(pid)
        if (time.monotonic() - t0) % 10 < 1:
            connect_all()
    viewer.join(15)
    for s in socks:
        s.close()
    return {**peak, **viewer.result(base)}


def slowloris(port: int, pid: int, base: float, seconds: float, n: int = 1000) -> dict[str, Any]:
    """``n`` connections sending one header byte every 5 s; a viewer streams meanwhile."""
    socks = [s for i in range(n) if (s := _connect(port, f"127.0.{1 + i // 250}.{2 + i % 250}")) is not None]
    for s in socks:
        with contextlib.suppress(OSError):
            s.sendall(b"GET /stream.mjpg HTTP/1.1\r\n")
    viewer = Viewer(port, seconds)
    viewer.start()
    t0, peak = time.monotonic(), figures(pid)
    while time.monotonic() - t0 < seconds:
        time.sleep(5)
        for s in socks:
            with contextlib.suppress(OSError):
                s.send(b"X")
        f = figures(pid)
        peak = f if f["threads"] >= peak["threads"] else peak
    alive = 0
    for s in socks:
        try:
            s.send(b"X")
            alive += 1
        except OSError:
            pass
        s.close()
    viewer.join(15)
    return {**peak, "attackers_open_at_end": alive, "connected": len(socks), **viewer.result(base)}


def burst(port: int, pid: int, base: float, n: int = 200) -> dict[str, Any]:
    """``n`` snapshot requests connecting at once: how many succeed, and the slowest."""
    times: list[float] = []
    failed = [0]
    go = threading.Event()

    def one(i: int) -> None:
        go.wait()
        t0 = time.monotonic()
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=30,
                                          source_address=(f"127.0.1.{2 + i}", 0)) as s:
                s.sendall(b"GET /snapshot.jpg HTTP/1.1\r\nHost: x\r\n\r\n")
                ok = s.recv(20).startswith(b"HTTP/1.")
            (times.append(time.monotonic() - t0) if ok else failed.__setitem__(0, failed[0] + 1))
        except OSError:
            failed[0] += 1

    clients = [Worker(one, i, name=f"bench-burst-{i}", join_timeout_s=40).start() for i in range(n)]
    viewer = Viewer(port, 8)
    viewer.start()
    time.sleep(0.5)
    go.set()
    peak = figures(pid)
    for c in clients:
        c.close()  # joined; what failed, other than a connection, is raised
    viewer.join(15)
    return {**peak, "answered": len(times), "failed": failed[0], "slowest_s": round(max(times, default=0), 2),
            **viewer.result(base)}


def fdlimit(seconds: float) -> dict[str, Any]:
    """The server under RLIMIT_NOFILE 128: a viewer streams, 200 idle connections exhaust the descriptors
    for ``seconds``; then they close and a second viewer must get frames."""
    proc, _, port = serve(nofile=128)
    try:
        time.sleep(1)
        base = idle_base(port)
        viewer = Viewer(port, seconds + 8)
        viewer.start()
        cpu0, t0 = figures(proc.pid)["cpu_s"], time.monotonic()
        time.sleep(3)
        share_before = (figures(proc.pid)["cpu_s"] - cpu0) / (time.monotonic() - t0)
        socks = [s for i in range(200) if (s := _connect(port, f"127.0.2.{2 + i}")) is not None]
        for s in socks:  # slowloris-style, so that no idle timeout frees the descriptors during the window
            with contextlib.suppress(OSError):
                s.send(b"GET / HTTP/1.1\r\n")
        cpu0, t0, peak = figures(proc.pid)["cpu_s"], time.monotonic(), figures(proc.pid)
        while time.monotonic() - t0 < seconds:
            time.sleep(2)
            for s in socks:
                with contextlib.suppress(OSError):
                    s.send(b"X")
            f = figures(proc.pid)
            peak = f if f["fds"] >= peak["fds"] else peak
        cpu_share = (figures(proc.pid)["cpu_s"] - cpu0) / (time.monotonic() - t0)
        for s in socks:
            s.close()
        time.sleep(2)
        after = Viewer(port, 3)
        after.start()
        after.join(20)
        viewer.join(20)
        return {**peak, "cpu_share_before": round(share_before, 2), "cpu_share_during": round(cpu_share, 2),
                **viewer.result(base),
                "new_client_after": after.result(base)}
    finally:
        stop(proc)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="shorter attacks (about 1 minute in all)")
    p.add_argument("--only", nargs="*", default=None, help="attack names to run")
    args = p.parse_args(argv)
    seconds = 12 if args.quick else 25
    resource.setrlimit(resource.RLIMIT_NOFILE, (4096, resource.getrlimit(resource.RLIMIT_NOFILE)[1]))
    results: dict[str, Any] = {}
    attacks = {"lockout": lambda port, pid, base: lockout(port, pid, base, seconds, 1),
               "lockout32": lambda port, pid, base: lockout(port, pid, base, seconds, 32),
               "slowloris": lambda port, pid, base: slowloris(port, pid, base, seconds),
               "burst": burst}
    for name, attack in attacks.items():
        if args.only is not None and name not in args.only:
            continue
        proc, _, port = serve()
        try:
            time.sleep(1)
            base = idle_base(port)
            idle = figures(proc.pid)
            results[name] = {"idle": idle, "attack": attack(port, proc.pid, base)}
        finally:
            stop(proc)
        print(name, json.dumps(results[name]), flush=True)
    if args.only is None or "fdlimit" in args.only:
        results["fdlimit"] = {"attack": fdlimit(6)}
        print("fdlimit", json.dumps(results["fdlimit"]), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
