"""Transports with real clients: cv2.VideoCapture on the MJPEG stream, pyserial on the pty and the
rollcam:// URL handler, ``rollcam emulate`` end to end; slow, malformed and fuzzed HTTP clients."""

from __future__ import annotations

import json
import os
import re
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request

import cv2
import pytest
import serial
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from interrupts import interrupt
from rollcam.emu.http.mjpeg import MjpegServer
from rollcam.emu.http.server import HttpLimits
from rollcam.emu.protocol_rollcam import register_camera
from rollcam.emu.serial_pty import PtySerialServer
from rollcam.firmware.camera import FirmwareCamera

FUZZ_COUNTS: dict[str, int] = {}


def camera(**kw) -> FirmwareCamera:
    return FirmwareCamera("imx219", scene=kw.pop("scene", {"scene": "flat"}), size=(640, 480), **kw)


@pytest.fixture(scope="module")
def server():
    with MjpegServer(camera(scene={"scene": "chart"})) as srv:
        yield srv


def status(srv: MjpegServer) -> dict:
    with urllib.request.urlopen(srv.url.replace("stream.mjpg", "status.json"), timeout=5) as r:
        return json.load(r)


def test_opencv_reads_the_stream_with_several_clients_at_once(server):
    results: dict[int, list] = {}

    def read(i: int) -> None:
        cap = cv2.VideoCapture(server.url)
        shapes = []
        for _ in range(5):
            ok, img = cap.read()
            shapes.append(img.shape if ok else None)
        cap.release()
        results[i] = shapes

    threads = [threading.Thread(target=read, args=(i,)) for i in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert results == {i: [(480, 640, 3)] * 5 for i in range(3)}


def _parts(url: str, n: int) -> list[dict[str, str]]:
    heads = []
    with urllib.request.urlopen(url, timeout=5) as r:
        assert r.headers["Content-Type"].startswith("multipart/x-mixed-replace; boundary=")
        while len(heads) < n:
            line = r.readline().strip()
            if line != b"--rollcamframe":
                continue
            head = {}
            while (line := r.readline().strip()):
                k, v = line.decode().split(": ", 1)
                head[k] = v
            r.read(int(head["Content-Length"]))
            heads.append(head)
    return heads


def test_parts_carry_sequence_and_device_timestamps(server):
    heads = _parts(server.url, 4)
    seqs = [int(h["X-Sequence"]) for h in heads]
    assert seqs == sorted(seqs) and len(set(seqs)) == 4
    timing = server.camera.state.timing
    t = [int(h["X-Timestamp-Ns"]) for h in heads]
    assert t[1] - t[0] == timing.frame_start_ns(seqs[1]) - timing.frame_start_ns(seqs[0])
    assert heads[0]["X-Line-Time-Ns"] == str(timing.line_time_ns) and heads[0]["X-Readout"] == "top_to_bottom"


def test_slow_client_drops_frames_and_others_keep_streaming():
    cam = camera()
    cam.set_control("test_pattern", 4)  # PN9 noise: large JPEGs fill socket buffers quickly
    with MjpegServer(cam, quality=100) as srv:
        slow = socket.socket()
        slow.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        slow.connect(srv.address)
        slow.sendall(b"GET /stream.mjpg HTTP/1.1\r\nHost: x\r\n\r\n")
        slow.recv(100)  # the stream started; now stop reading
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            st_ = status(srv)
            slow_stats = [c for c in st_["clients"].values() if c["dropped"] > 0]
            if slow_stats:
                break
            time.sleep(0.2)
        assert slow_stats, st_
        assert len(_parts(srv.url, 3)) == 3  # a new client is served while the slow one stalls
        slow.close()
    assert srv.closed


def test_client_leaving_mid_frame_costs_nothing(server):
    before = status(server)["clients_served"]
    for _ in range(3):
        with socket.create_connection(server.address, timeout=5) as s:
            s.sendall(b"GET /stream.mjpg HTTP/1.1\r\nHost: x\r\n\r\n")  # HTTP/1.1 requires Host (RFC 9112)
            assert s.recv(300).startswith(b"HTTP/1.1 200")  # then hang up inside the first part
    deadline = time.monotonic() + 10
    while status(server)["clients"] and time.monotonic() < deadline:
        time.sleep(0.1)
    st_ = status(server)
    assert st_["clients_served"] >= before + 3 and st_["clients"] == {}
    assert len(_parts(server.url, 2)) == 2


def _http_exchange(addr: tuple[str, int], request: bytes) -> bytes:
    with socket.create_connection(addr, timeout=5) as s:
        s.sendall(request)
        s.shutdown(socket.SHUT_WR)
        try:
            return s.recv(200)
        except (TimeoutError, ConnectionResetError):
            return b""


@pytest.mark.parametrize(("request_bytes", "code"), [
    (b"GARBAGE\r\n\r\n", b"400"),
    (b"GET /nope HTTP/1.1\r\nHost: x\r\n\r\n", b"404"),
    (b"GET /nope HTTP/1.1\r\n\r\n", b"400"),  # HTTP/1.1 without Host (RFC 9112)
    (b"POST /stream.mjpg HTTP/1.1\r\nHost: x\r\nContent-Length: 0\r\n\r\n", b"405"),
    (b"GET / HTTP/9.9\r\n\r\n", b"400"),  # aiohttp's parser takes HTTP/1.x only
    (b"GET /" + b"a" * 70000 + b" HTTP/1.1\r\n\r\n", b"414"),
])
def test_malformed_requests_get_an_http_error_and_the_server_keeps_serving(server, request_bytes, code):
    reply = _http_exchange(server.address, request_bytes)
    assert reply.split(b" ")[1] == code, reply
    assert len(_parts(server.url, 1)) == 1


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(st.one_of(
    st.binary(max_size=400),
    st.tuples(st.sampled_from([b"GET", b"POST", b"HEAD", b"get", b"", b"\x00"]),
              st.sampled_from([b"/", b"/stream.mjpg", b"/status.json", b"/snapshot.jpg", b"/x", b"", b"*"]),
              st.sampled_from([b"HTTP/1.1", b"HTTP/1.0", b"HTTP/2", b"", b"HTTP/x"]),
              st.binary(max_size=100)).map(lambda p: p[0] + b" " + p[1] + b" " + p[2] + b"\r\n" + p[3]),
))
def _fuzz_http(addr, data):
    FUZZ_COUNTS["http"] = FUZZ_COUNTS.get("http", 0) + 1
    reply = _http_exchange(addr, data + b"\r\n\r\n")
    assert reply == b"" or reply.startswith((b"HTTP/1.0 ", b"HTTP/1.1 ")), reply


def test_fuzz_http_requests(server):
    FUZZ_COUNTS["http"] = 0
    _fuzz_http(server.address)
    assert FUZZ_COUNTS["http"] >= 100
    assert len(_parts(server.url, 2)) == 2  # still streaming after the fuzzing
    print(f"HTTP request fuzz: {FUZZ_COUNTS['http']} inputs")


def test_pyserial_talks_to_the_pty():
    cam = camera()
    with PtySerialServer(cam) as srv:
        with serial.Serial(srv.path, 115200, timeout=5) as port:
            port.write(b"*IDN?\r\n")
            assert port.readline() == b"rollcam,IMX219-EMU,0001,1.0.0\r\n"
            port.write(b"REG 0x0160 2000\nSTREAM ON\nBOGUS\n")
            assert [port.readline() for _ in range(3)] == [b"OK 0x07D0\r\n", b"OK\r\n",
                                                           b"ERR 100 unknown command 'BOGUS'; try HELP\r\n"]
        assert cam.streaming and cam.state.frame_length_lines == 2000
        with serial.Serial(srv.path, timeout=5) as port:  # a second open of the same port
            port.write(b"CLOCK?\n")
            assert int(port.readline()) > 0
        master = srv._master
    assert srv.closed
    with pytest.raises(OSError):
        os.fstat(master)  # the pty's descriptors are closed
    srv.close()  # twice is harmless


def test_pyserial_url_handler_in_process():
    serial.protocol_handler_packages.append("rollcam.emu")
    try:
        with serial.serial_for_url("rollcam://ov9281?scene=flat", timeout=2) as port:
            port.write(b"*IDN?\nREG? CHIP_ID\n")
            assert port.readline() == b"rollcam,OV9281-EMU,0001,1.0.0\r\n"
            assert port.readline() == b"0x9281\r\n"
        cam = camera()
        register_camera("bench0", cam)
        with serial.serial_for_url("rollcam://bench0", timeout=2) as port:
            port.write(b"CTRL vblank 100\n")
            assert port.readline() == b"OK 100\r\n"
        assert cam.get_control("vblank") == 100
        with pytest.raises(serial.SerialException, match="no sensor named"):
            serial.serial_for_url("rollcam://nosuch")
    finally:
        serial.protocol_handler_packages.remove("rollcam.emu")


def test_rollcam_emulate_serves_until_interrupted_and_frees_its_port():
    cmd = [sys.executable, "-m", "rollcam.host.cli", "emulate", "imx219", "--size", "640x480", "--scene", "flat",
           "--http", "127.0.0.1:0", "--serial", "--json", "--duration", "60"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        info = json.loads(proc.stdout.readline())
        url, path = info["http"]["url"], info["serial"]["path"]
        cap = cv2.VideoCapture(url)
        ok, img = cap.read()
        cap.release()
        assert ok and img.shape == (480, 640, 3)
        with serial.Serial(path, timeout=5) as port:
            port.write(b"*IDN?\n")
            assert port.readline().startswith(b"rollcam,IMX219-EMU,")
        _out, err = interrupt(proc, 30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    m = re.search(r"stopped; (\d+) frames made \((\d+) delivered by the pump, (\d+) remade", err)
    assert m, err  # frames made count those made ahead; delivered ones reached the clients
    assert int(m[1]) >= int(m[2]) >= 1
    host, port_ = url.split("/")[2].split(":")
    with pytest.raises(OSError):
        socket.create_connection((host, int(port_)), timeout=2).close()


def test_rollcam_emulate_warns_when_bound_wider():
    cmd = [sys.executable, "-m", "rollcam.host.cli", "emulate", "imx219", "--size", "640x480", "--scene", "flat",
           "--http", "0.0.0.0:0", "--duration", "0.5"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and "warning: HTTP bound to '0.0.0.0'" in done.stderr


def test_snapshot_and_status(server):
    with urllib.request.urlopen(server.url.replace("stream.mjpg", "snapshot.jpg"), timeout=5) as r:
        assert r.headers["Content-Type"] == "image/jpeg" and r.read(2) == b"\xff\xd8"
    before = status(server)
    assert before["frames_encoded"] > 0
    with pytest.raises(urllib.error.HTTPError) as info:
        urllib.request.urlopen(server.url.replace("stream.mjpg", "missing"), timeout=5)
    assert info.value.code == 404
    assert status(server)["bad_requests"] == before["bad_requests"] + 1


def test_pty_client_that_never_reads_costs_dropped_replies_not_memory():
    with PtySerialServer(camera()) as srv, serial.Serial(srv.path, timeout=5, write_timeout=10) as port:
        port.write(b"*IDN?\n" * 3000)  # ~90 kB of replies, far more than a pty buffers
        deadline = time.monotonic() + 20
        while srv.session.lines < 3000 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert srv.session.lines == 3000 and srv.stats.dropped_bytes > 0
        port.reset_input_buffer()
        time.sleep(0.2)
        port.reset_input_buffer()
        port.write(b"STATS?\n")
        assert port.readline().startswith(b"frames=")  # still answering


def test_client_limit_answers_503_and_frees_the_slot():
    with MjpegServer(camera(), limits=HttpLimits(max_streams=1, admit_wait_s=0.5)) as srv:
        first = urllib.request.urlopen(srv.url, timeout=5)
        stop = threading.Event()
        reading = threading.Thread(target=lambda: [first.read(4096) for _ in iter(stop.is_set, True)], daemon=True)
        reading.start()  # a live reader keeps its slot (a silent one would yield it: tests/test_http_attacks.py)
        with pytest.raises(urllib.error.HTTPError) as info:
            urllib.request.urlopen(srv.url, timeout=5)
        assert info.value.code == 503
        stop.set()
        reading.join(10)
        first.close()
        deadline = time.monotonic() + 10
        while srv.clients and time.monotonic() < deadline:
            time.sleep(0.1)
        assert len(_parts(srv.url, 1)) == 1


def test_rollcam_emulate_bad_input_exits_2():
    cmd = [sys.executable, "-m", "rollcam.host.cli", "emulate", "nosuch", "--duration", "0.1"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "no sensor named 'nosuch'" in done.stderr
    cmd = [sys.executable, "-m", "rollcam.host.cli", "emulate", "imx219", "--http", "localhost:http"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "expected HOST:PORT" in done.stderr
