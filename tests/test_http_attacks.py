"""The attacks of issue 11 on the HTTP MJPEG server, each reproduced on loopback with small limits.

Attackers come from 127.0.0.2 and up (Linux routes all of 127/8 to loopback), the normal client from
127.0.0.1, so per-address limits are visible. Every wait is bounded; every attack ends by itself.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from collections.abc import Iterator

import pytest
import rollcam.host  # noqa: F401  (registers the in-sensor network loader the insensor= option needs)
from helpers import wait_for
from rollcam.emu.http.mjpeg import MjpegServer
from rollcam.emu.http.server import HttpLimits
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.spec import CameraSpec

GET = b"GET /stream.mjpg HTTP/1.1\r\nHost: x\r\n\r\n"


def camera(noise: bool = False, **kw) -> FirmwareCamera:
    cam = FirmwareCamera("imx219", scene={"scene": "flat"}, size=(640, 480), **kw)
    if noise:
        cam.set_control("test_pattern", 4)  # PN9 noise: large JPEGs fill socket buffers quickly
    return cam


def status(srv: MjpegServer) -> dict:
    with urllib.request.urlopen(srv.url.replace("stream.mjpg", "status.json"), timeout=10) as r:
        return json.load(r)


def attacker(addr: tuple[str, int], source: str, request: bytes = GET, rcvbuf: int | None = 4096) -> socket.socket:
    """A connection from ``source`` that sends ``request`` and then never reads."""
    s = socket.socket(socket.AF_INET6 if ":" in addr[0] else socket.AF_INET)
    if rcvbuf:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
    s.bind((source, 0))
    s.settimeout(5)
    s.connect(addr)
    if request:
        s.sendall(request)
    return s


class Reader(threading.Thread):
    """A normal client from 127.0.0.1 reading the stream until stopped, counting the parts it gets."""

    def __init__(self, addr: tuple[str, int]) -> None:
        super().__init__(daemon=True)
        self.addr, self.parts, self.status = addr, 0, b""
        self.stop = threading.Event()

    def run(self) -> None:
        with contextlib.suppress(OSError), socket.create_connection(self.addr, timeout=10) as s:
            s.sendall(GET)
            f = s.makefile("rb")
            self.status = f.readline()
            while not self.stop.is_set():
                line = f.readline()
                if not line:
                    return
                if line.lower().startswith(b"content-length:"):
                    while f.readline().strip():  # the part's other headers
                        pass
                    f.read(int(line.split(b":")[1]))
                    self.parts += 1

    def __enter__(self) -> Reader:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.join(15)


def closed_by_server(s: socket.socket) -> bool:
    """True when the server has closed ``s`` (whatever it sent first)."""
    s.setblocking(False)
    try:
        while True:
            if s.recv(65536) == b"":
                return True
    except BlockingIOError:
        return False
    except OSError:
        return True
    finally:
        s.setblocking(True)


@contextlib.contextmanager
def sockets() -> Iterator[list[socket.socket]]:
    held: list[socket.socket] = []
    try:
        yield held
    finally:
        for s in held:
            s.close()


def test_non_reading_streams_cannot_lock_out_a_reader():
    """32 silent stream requests held every slot on main; here stalled streams yield their slots and one
    address holds at most its share."""
    limits = HttpLimits(max_streams=3, max_streams_per_peer=2, stall_s=0.3, send_timeout_s=60)
    with MjpegServer(camera(noise=True), quality=100, limits=limits) as srv, sockets() as held:
        held += [attacker(srv.address, f"127.0.0.{2 + i % 2}", rcvbuf=None) for i in range(3)]
        assert wait_for(lambda: len(srv.clients) == 3 and all(
            c.stalled_s(srv.http.loop.time()) >= 0.3 for c in srv.clients.values()))
        third = attacker(srv.address, "127.0.0.2", rcvbuf=None)  # over the per-address limit: evicts its own
        held.append(third)
        assert wait_for(lambda: status(srv)["evicted_stalled"] >= 1)
        with Reader(srv.address) as reader:
            assert wait_for(lambda: reader.parts >= 3), reader.status
            for round_ in range(2):  # the attackers reconnect; the reader keeps its slot and its frames
                for s in held:
                    s.close()
                held[:] = [attacker(srv.address, f"127.0.0.{2 + i}", rcvbuf=None) for i in range(3)]
                before = reader.parts
                assert wait_for(lambda before=before: reader.parts >= before + 3), round_
        st = status(srv)
        assert st["evicted_stalled"] >= 2
        per_peer: dict[str, int] = {}
        for c in st["clients"].values():
            per_peer[c["peer"]] = per_peer.get(c["peer"], 0) + 1
        assert max(per_peer.values()) <= 2


def test_live_streams_are_refused_by_address_then_in_all():
    limits = HttpLimits(max_streams=2, max_streams_per_peer=1, stall_s=30, admit_wait_s=0.5)
    with MjpegServer(camera(), limits=limits) as srv, Reader(srv.address) as r1:
        assert wait_for(lambda: r1.parts >= 1)
        with pytest.raises(urllib.error.HTTPError) as info:  # a second live stream from 127.0.0.1
            urllib.request.urlopen(srv.url, timeout=5)
        assert info.value.code == 503 and b"too many streams from 127.0.0.1 (max 1)" in info.value.read()
        with sockets() as held:
            held.append(attacker(srv.address, "127.0.0.2", rcvbuf=None))
            assert held[0].recv(12) == b"HTTP/1.1 200"
            held.append(attacker(srv.address, "127.0.0.3", rcvbuf=None))
            assert held[1].recv(12) == b"HTTP/1.1 503"  # full, and nobody is stalled
        assert r1.parts >= 1 and r1.is_alive()


def test_slowloris_is_cut_off_by_the_request_deadline():
    """1,000 trickling headers held 1,000 threads on main; here each connection gets request_timeout_s for its
    whole request, and past max_connections a newcomer evicts the oldest one still waiting."""
    limits = HttpLimits(request_timeout_s=1.0, max_connections=12)
    with MjpegServer(camera(), limits=limits) as srv, Reader(srv.address) as reader, sockets() as held:
        assert wait_for(lambda: reader.parts >= 1)
        threads_before = threading.active_count()
        for i in range(20):
            held.append(attacker(srv.address, f"127.0.0.{2 + i}", b"GET /stream.mjpg HTTP/1.1\r\n", rcvbuf=None))
        assert threading.active_count() == threads_before  # no thread per connection
        assert srv.http.stats.connections_open <= limits.max_connections
        for _ in range(15):  # one header byte each every 0.2 s: 3 s, three deadlines
            for s in held:
                with contextlib.suppress(OSError):
                    s.send(b"X")
            time.sleep(0.2)
        assert all(closed_by_server(s) for s in held)
        st = status(srv)["http"]
        assert st["request_timeouts"] + st["evicted_waiting"] >= 20, st
        assert reader.parts >= 3 and reader.is_alive()  # served throughout


@pytest.mark.parametrize(("head", "code"), [
    (b"GET /" + b"a" * 2000 + b" HTTP/1.1\r\nHost: x\r\n\r\n", b"414"),
    (b"GET / HTTP/1.1\r\nHost: x\r\nX-Big: " + b"b" * 2000 + b"\r\n\r\n", b"431"),
    (b"GET / HTTP/1.1\r\nHost: x\r\n" + b"".join(b"X-%d: y\r\n" % i for i in range(20)) + b"\r\n", b"400"),
])
def test_request_head_limits(head, code):
    limits = HttpLimits(max_request_bytes=1024, max_headers=8)
    with MjpegServer(camera(), limits=limits) as srv:
        with socket.create_connection(srv.address, timeout=5) as s:
            s.sendall(head)
            reply = s.recv(200)
        assert reply.split(b" ")[1] == code, reply
        with Reader(srv.address) as r:  # still serving
            assert wait_for(lambda: r.parts >= 1)


def test_listen_backlog_is_sane():
    if shutil.which("ss") is None:
        pytest.skip("ss (iproute2) is not installed")
    with MjpegServer(camera(), limits=HttpLimits(backlog=128)) as srv:
        port = srv.address[1]
        out = subprocess.run(["ss", "-ltnH", f"sport = :{port}"], capture_output=True, text=True, timeout=10).stdout
    send_q = int(out.split()[2])  # a listening socket's Send-Q is its backlog
    assert send_q == 128, out


def test_departed_clients_free_their_slots_with_the_stream_off():
    """On main a client that left while the stream was off kept its slot until the stream came back."""
    with MjpegServer(camera(), max_clients=2) as srv:
        srv.camera.stream_off()
        with sockets() as held:
            held += [attacker(srv.address, f"127.0.0.{2 + i}", rcvbuf=None) for i in range(2)]
            assert all(s.recv(12) == b"HTTP/1.1 200" for s in held)
            assert len(srv.clients) == 2
        assert wait_for(lambda: not srv.clients, timeout_s=5)
        srv.camera.stream_on()
        with Reader(srv.address) as r:
            assert wait_for(lambda: r.parts >= 1)


def test_stalled_clients_cost_a_bounded_write_buffer_and_count_drops():
    limits = HttpLimits(stall_s=0.3, send_timeout_s=60)
    with MjpegServer(camera(noise=True), quality=100, limits=limits) as srv, sockets() as held:
        held += [attacker(srv.address, f"127.0.0.{2 + i}") for i in range(4)]
        assert wait_for(lambda: sum(c["dropped"] > 0 for c in status(srv)["clients"].values()) == 4)
        biggest = max(len(c.item.chunk) for c in srv.clients.values() if c.item is not None)
        for c in status(srv)["clients"].values():
            assert c["backlog_bytes"] <= biggest + 64 * 1024, c  # one part and the high-water mark, no queue


def test_send_timeout_closes_a_stalled_stream():
    limits = HttpLimits(stall_s=0.2, send_timeout_s=1.0)
    with MjpegServer(camera(noise=True), quality=100, limits=limits) as srv, sockets() as held:
        held.append(attacker(srv.address, "127.0.0.2"))
        assert wait_for(lambda: status(srv)["send_timeouts"] == 1)
        assert srv.clients == {}


@pytest.mark.parametrize(("path", "query"), [("/imu.jsonl", "from_ns=4000000000000000000"),
                                             ("/insensor.jsonl", "from_seq=4000000000000000000")])
def test_idle_json_lines_readers_cannot_lock_out_a_reader(path: str, query: str):
    """Issue 37 J2: 8 readers asking for a device time far in the future held every JSON-lines slot on main (503
    for everyone else); here they count as stalled, one address holds at most its share, a newcomer evicts the
    idlest, and the sweep closes them at the deadline."""
    limits = HttpLimits(stall_s=0.3, admit_wait_s=3.0, send_timeout_s=2.0)
    cam = FirmwareCamera(CameraSpec.from_options("imx219", {"size": "320x180", "scene": "flat", "imu": "on",
                                                            "insensor": "personnet-raw"}))
    request = f"GET {path}?{query} HTTP/1.1\r\nHost: x\r\n\r\n".encode()
    with MjpegServer(cam, limits=limits) as srv, sockets() as held:
        for _ in range(8):
            held.append(attacker(srv.address, "127.0.0.2", request=request))
            assert held[-1].recv(12) == b"HTTP/1.1 200"
        base = f"http://127.0.0.1:{srv.address[1]}"
        with urllib.request.urlopen(f"{base}{path}?{'samples' if 'imu' in path else 'results'}=1", timeout=20) as r:
            lines = r.read().decode().splitlines()  # main: HTTP 503 "8 ... streams already"
        assert len(lines) == 2 and "error" not in lines[-1], lines
        st = status(srv)["jsonl"][path]
        assert st["served"] == 9 and st["readers"] <= 4 + 1  # at most 4 from one address: its own idlest evicted
        assert wait_for(lambda: status(srv)["jsonl"][path]["closed_stalled"] >= 1)  # the idle deadline


def _has_ipv6_loopback() -> bool:
    try:
        with socket.socket(socket.AF_INET6) as s:
            s.bind(("::1", 0))
        return True
    except OSError:
        return False


@pytest.mark.skipif(not _has_ipv6_loopback(), reason="no IPv6 loopback (::1) on this machine")
def test_ipv6_emulate_http():
    cmd = [sys.executable, "-m", "rollcam.host.cli", "emulate", "imx219", "--scene", "flat", "--size", "640x480",
           "--http", "[::1]:0", "--json", "--duration", "30"]
    with subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as proc:
        try:
            line = proc.stdout.readline()
            url = json.loads(line)["http"]["url"]
            assert url.startswith("http://[::1]:")
            with urllib.request.urlopen(url, timeout=10) as r:
                assert r.headers["Content-Type"].startswith("multipart/x-mixed-replace")
                assert r.readline().strip() == b"--rollcamframe"
        finally:
            proc.terminate()
            proc.wait(30)


FD_SERVER = """
import os, resource, sys, time
from rollcam.emu.http.mjpeg import MjpegServer
from rollcam.emu.http.server import HttpLimits
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.spec import CameraSpec
cam = FirmwareCamera("imx219", scene={"scene": "flat"}, size=(640, 480), fps=10)
with MjpegServer(cam, limits=HttpLimits(request_timeout_s=60, max_connections=1000)) as srv:
    n = len(os.listdir("/proc/self/fd"))
    resource.setrlimit(resource.RLIMIT_NOFILE, (n + 12, resource.getrlimit(resource.RLIMIT_NOFILE)[1]))
    print(srv.address[1], flush=True)
    sys.stdin.read()
"""


def _cpu_s(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def test_descriptor_limit_sheds_without_spinning_and_recovers():
    """On main the accept loop spun at 100 % CPU at the descriptor limit; here accepting pauses, streams
    already open go on, and new clients are served once descriptors free."""
    with subprocess.Popen([sys.executable, "-c", FD_SERVER], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                          text=True) as proc:
        try:
            port = int(proc.stdout.readline())
            addr = ("127.0.0.1", port)
            with Reader(addr) as reader:
                assert wait_for(lambda: reader.parts >= 1)
                with sockets() as held:
                    held += [attacker(addr, f"127.0.0.{2 + i}", request=b"", rcvbuf=None) for i in range(30)]
                    cpu0, t0 = _cpu_s(proc.pid), time.monotonic()
                    parts0 = reader.parts
                    time.sleep(3)
                    share = (_cpu_s(proc.pid) - cpu0) / (time.monotonic() - t0)
                    assert share < 0.5, f"server used {share:.0%} of a CPU at the descriptor limit"
                    assert reader.parts > parts0  # the open stream goes on
                with Reader(addr) as late:
                    assert wait_for(lambda: late.parts >= 1)
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/status.json", timeout=10) as r:
                assert json.load(r)["http"]["accept_paused"] >= 1
        finally:
            proc.stdin.close()
            proc.wait(30)



def test_ffmpeg_reads_the_stream():
    """The wire format is what real clients expect: ffmpeg (imageio-ffmpeg's binary) decodes the parts."""
    ffmpeg = pytest.importorskip("imageio_ffmpeg").get_ffmpeg_exe()
    with MjpegServer(camera()) as srv:
        done = subprocess.run([ffmpeg, "-hide_banner", "-nostdin", "-f", "mpjpeg", "-i", srv.url, "-frames:v", "3",
                               "-f", "null", "-"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "frame=    3" in done.stderr or "frame=3" in done.stderr.replace(" ", ""), done.stderr[-2000:]
