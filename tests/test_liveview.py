"""The live view's server side without a browser: the token off loopback, the page beside an unchanged MJPEG
``/``, frames with truth on the WebSocket, controls through the camera's one path, a stalled page that holds
up nobody, snapshots, detections, and ``rollcam view`` on host sources."""

from __future__ import annotations

import asyncio
import base64
import json
import socket
import struct
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from typing import Any

import aiohttp
import cv2
import numpy as np
import pytest
from rollcam.common.errors import ConfigError
from rollcam.emu.http.mjpeg import MjpegServer
from rollcam.emu.http.view import LiveView, host_names_server, is_loopback
from rollcam.emu.http.view_controls import EGO_PRESETS, CameraControls, NoControls
from rollcam.firmware.camera import FirmwareCamera
from rollcam.sim.scenegen import ego_preset


def camera(**kw: Any) -> FirmwareCamera:
    return FirmwareCamera("imx219", size=(320, 240), scene={"scene": "street", "seed": 1}, **kw)


def served(host: str = "127.0.0.1", annotate: Callable | None = None) -> tuple[MjpegServer, LiveView]:
    cam = camera()
    srv = MjpegServer(cam, host, 0)
    return srv, LiveView(srv, CameraControls(cam), annotate=annotate)


def local(srv: MjpegServer) -> str:
    return f"http://127.0.0.1:{srv.address[1]}"


def frame_of(data: bytes) -> tuple[dict[str, Any], bytes]:
    n = struct.unpack(">I", data[:4])[0]
    return json.loads(data[4:4 + n]), data[4 + n:]


async def frames(ws: aiohttp.ClientWebSocketResponse, n: int, on_text: Callable | None = None) -> list[dict]:
    got = []
    async for msg in ws:
        if msg.type == aiohttp.WSMsgType.BINARY:
            got.append(frame_of(msg.data)[0])
            if len(got) >= n:
                return got
        elif on_text is not None:
            on_text(json.loads(msg.data))
    raise AssertionError(f"the WebSocket closed after {len(got)} frames")


@pytest.fixture
def view() -> Iterator[tuple[MjpegServer, LiveView]]:
    srv, lv = served()
    with srv, lv:
        yield srv, lv


def test_loopback_is_told_apart():
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost") and is_loopback("127.4.0.1")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.2") and not is_loopback("::")


def test_the_token_is_required_off_loopback_for_page_websocket_and_snapshot():
    srv, lv = served("0.0.0.0")
    with srv, lv:
        assert lv.token and lv.url.endswith(f"/?token={lv.token}")
        base, html = local(srv), {"Accept": "text/html"}

        async def run() -> None:
            async with aiohttp.ClientSession() as s:
                for path in ("/", "/view", "/view/state.json", "/view/snapshot.json", "/?token=wrong"):
                    async with s.get(base + path, headers=html) as r:
                        assert r.status == 401, path
                        assert "token" in await r.text()
                with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                    await s.ws_connect(base + "/view/ws")
                assert refused.value.status == 401
                async with s.get(f"{base}/?token={lv.token}", headers=html) as r:
                    assert r.status == 200 and "rollcam live view" in await r.text()
                async with s.get(base + "/view/view.js") as r:  # the script is no secret
                    assert r.status == 200
                with pytest.raises(aiohttp.WSServerHandshakeError) as other_site:
                    await s.ws_connect(f"{base}/view/ws?token={lv.token}", origin="http://evil.example")
                assert other_site.value.status == 403
                async with s.ws_connect(f"{base}/view/ws?token={lv.token}") as ws:
                    assert len(await frames(ws, 2)) == 2

        asyncio.run(run())
        assert lv.stats.refused_auth >= 6


def test_a_rebound_name_cannot_reach_the_view_on_loopback(view):
    """DNS rebinding (issue 37 V2): evil.example resolved to 127.0.0.1 sends Origin and Host evil.example:PORT.
    On main the WebSocket changed the gain and state/snapshot answered; here each is refused (403) unless the
    Host names this server."""
    srv, lv = view
    port = srv.address[1]
    evil = {"Host": f"evil.example:{port}", "Origin": f"http://evil.example:{port}", "Accept": "text/html"}
    gain = srv.camera.spec.option_values()["gain"]

    async def run() -> None:
        async with aiohttp.ClientSession() as s:
            for path in ("/", "/view", "/view/state.json", "/view/snapshot.json"):
                async with s.get(local(srv) + path, headers=evil) as r:
                    assert r.status == 403, path
                    assert "evil.example" in await r.text()
            with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                await s.ws_connect(local(srv) + "/view/ws", headers=evil)
            assert refused.value.status == 403
            async with s.get(local(srv) + "/view/view.js", headers=evil) as r:  # the script is public anyway
                assert r.status == 200
            for host in (f"localhost:{port}", f"127.0.0.1:{port}"):  # this server by its names: served
                async with s.get(local(srv) + "/view/state.json", headers={"Host": host}) as r:
                    assert r.status == 200, host
            async with s.ws_connect(local(srv) + "/view/ws", headers={"Host": f"localhost:{port}"},
                                    origin=f"http://localhost:{port}") as ws:
                assert len(await frames(ws, 1)) == 1

    asyncio.run(run())
    assert srv.camera.spec.option_values()["gain"] == gain
    assert lv.stats.refused_auth >= 5


@pytest.mark.parametrize(("host", "bound", "ok"), [
    ("127.0.0.1:8080", ("127.0.0.1", 8080), True), ("localhost:8080", ("127.0.0.1", 8080), True),
    ("[::1]:8080", ("::1", 8080), True), ("127.0.0.1:8081", ("127.0.0.1", 8080), False),
    ("127.0.0.1", ("127.0.0.1", 8080), False), ("evil.example:8080", ("127.0.0.1", 8080), False),
    ("evil.example:8080", ("0.0.0.0", 8080), False), ("192.168.1.5:8080", ("0.0.0.0", 8080), True),
    ("192.168.1.5:8080", ("10.0.0.1", 8080), False), ("10.0.0.1:8080", ("10.0.0.1", 8080), True),
    ("127.0.0.1:x", ("127.0.0.1", 8080), False), ("", ("127.0.0.1", 8080), False),
])
def test_host_names_this_server(host: str, bound: tuple[str, int], ok: bool):
    assert host_names_server(host, bound) is ok


def test_programs_asking_slash_still_get_the_mjpeg_stream(view):
    srv, _lv = view
    cap = cv2.VideoCapture(local(srv) + "/")
    ok, img = cap.read()
    cap.release()
    assert ok and img.shape == (240, 320, 3)


def test_frames_carry_their_truth_timing_and_the_shared_jpeg(view):
    srv, _lv = view

    async def run() -> list[tuple[dict, bytes]]:
        async with aiohttp.ClientSession() as s, s.ws_connect(local(srv) + "/view/ws") as ws:
            out = []
            async for msg in ws:
                if msg.type == aiohttp.WSMsgType.BINARY:
                    out.append(frame_of(msg.data))
                    if len(out) == 3:
                        return out
            return out

    got = asyncio.run(run())
    head, jpeg = got[-1]
    assert cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR).shape == (240, 320, 3)
    timing = srv.camera.spec.settings.timing
    assert head["line_time_ns"] == timing.line_time_ns and head["readout"] == "top_to_bottom"
    assert head["rows"][0] == [0, 0] and head["rows"][-1][0] == 239 and not head["by_column"]
    assert abs(head["rows"][-1][1] - timing.line_offset_ns(239)) <= 1  # the last tick: the last row's time
    assert head["objects"] and {"id", "box_gs", "box_rs", "speed_mps"} <= set(head["objects"][0])
    assert [h["seq"] for h, _ in got] == sorted(h["seq"] for h, _ in got)


def test_controls_from_the_socket_and_the_serial_side_are_one_path(view):
    from rollcam.firmware.protocol import handle_line

    srv, _lv = view
    cam = srv.camera

    async def run() -> list[dict]:
        texts: list[dict] = []
        async with aiohttp.ClientSession() as s, s.ws_connect(local(srv) + "/view/ws") as ws:
            await frames(ws, 1, texts.append)
            for i, (name, value) in enumerate([("gain", "2.5"), ("readout", "bt"), ("gain", "x"),
                                               ("nosuch", "1"), ("gain", "9" * 100)]):
                await ws.send_str(json.dumps({"type": "set", "id": i, "name": name, "value": value}))
            await ws.send_str("not json")
            while sum(t["type"] in ("applied", "error") for t in texts) < 6:
                await frames(ws, 1, texts.append)
            assert handle_line(cam, "OPT gain 1.5").startswith("OK")  # the serial door
            await frames(ws, 3, texts.append)  # the next frames bring the new state
        return texts

    texts = asyncio.run(run())
    replies = [t for t in texts if t["type"] in ("applied", "error")]
    assert [r["type"] for r in replies] == ["applied", "applied", "error", "error", "error", "error"]
    assert replies[0]["value"] == "2.5" and replies[1]["value"] == "bottom_to_top"
    assert "'x'" in replies[2]["message"] and "'nosuch'" in replies[3]["message"]
    assert cam.streaming and cam.spec.readout == "bottom_to_top"  # an idle-only option: restarted, streaming
    assert handle_line(cam, "OPT? readout") == "bottom_to_top"
    assert any(t["type"] == "state" and t["controls"]["gain"]["value"] == "1.5" for t in texts)  # serial -> page


def test_camera_controls_offer_only_what_the_scene_has_and_every_ego_preset_parses():
    flat = CameraControls(FirmwareCamera("imx219", size=(320, 240), scene={"scene": "flat"}))
    assert "speed" not in flat.describe() and "exposure_us" in flat.describe()
    with pytest.raises(ConfigError, match="'speed'"):
        flat.apply("speed", "fast")
    for name in EGO_PRESETS:
        ego_preset(name)
    with pytest.raises(ConfigError, match="no controls"):
        NoControls().apply("gain", "1")


def test_a_stalled_page_holds_up_neither_the_device_nor_another_page(view):
    srv, _lv = view
    host, port = srv.address
    stalled = socket.socket()
    stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    stalled.connect((host, port))
    stalled.sendall(f"GET /view/ws HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                    "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n".encode())
    try:  # it never reads again: once its buffers are full, newer frames replace the unsent one (drops)
        end = time.monotonic() + 20
        while not any(c["dropped"] > 0 for c in srv.status()["clients"].values()):
            assert time.monotonic() < end, srv.status()["clients"]
            time.sleep(0.1)

        async def run() -> list[dict]:  # a live page beside it keeps getting frames (if the stalled one held
            async with aiohttp.ClientSession() as s, s.ws_connect(local(srv) + "/view/ws") as ws:  # it, none)
                return await asyncio.wait_for(frames(ws, 40), 60)

        key, stuck = max(srv.status()["clients"].items(), key=lambda kc: kc[1]["dropped"])
        got = asyncio.run(run())
        assert len(got) == 40 and got[-1]["seq"] > got[0]["seq"]
        after = srv.status()
        if key in after["clients"]:  # skipped, never waited for
            now = after["clients"][key]
            assert now["dropped"] > stuck["dropped"] and now["sent"] == stuck["sent"]
        else:  # or, on a slow machine, closed for stalling past the send timeout
            assert after["send_timeouts"] >= 1
    finally:
        stalled.close()


def test_snapshot_is_the_frame_as_png_with_its_truth(view):
    srv, _lv = view

    async def run() -> dict:
        async with aiohttp.ClientSession() as s, s.get(local(srv) + "/view/snapshot.json") as r:
            assert r.status == 200
            return await r.json()

    doc = asyncio.run(run())
    png = cv2.imdecode(np.frombuffer(base64.b64decode(doc["png_base64"]), np.uint8), cv2.IMREAD_COLOR)
    assert png.shape == (240, 320, 3)
    assert doc["name"] == f"rollcam-{doc['truth']['seq']:06d}" and doc["truth"]["objects"]


def test_detections_come_from_the_newest_frame_and_a_failing_detector_is_reported():
    calls: list[int] = []

    def annotate(frame):
        calls.append(frame.sequence)
        if len(calls) == 2:
            raise RuntimeError("model broke")
        return [{"box": [1, 2, 30, 40], "score": 0.9, "cls": 0, "class_name": "person"}]

    srv, lv = served(annotate=annotate)
    with srv, lv:
        async def run() -> list[dict]:
            async with aiohttp.ClientSession() as s, s.ws_connect(local(srv) + "/view/ws") as ws:
                return await frames(ws, 12)

        got = asyncio.run(run())
    dets = [h["detections"] for h in got if h["detections"]]
    assert dets and dets[-1]["boxes"][0]["class_name"] == "person" and dets[-1]["seq"] <= got[-1]["seq"]
    assert lv.tap.stats.annotate_errors == 1 and lv.tap.stats.annotated >= 1


def test_rollcam_view_serves_a_host_source_with_the_controls_it_has(tmp_path):
    from rollcam.host.servers.view import open_view
    from rollcam.host.sources import open_camera

    with open_view(open_camera("emu:imx219?size=320x240&scene=chart"), paced=True) as running:
        srv = running.server
        assert "exposure_us" in running.view.controls.describe()

        async def run() -> list[dict]:
            async with aiohttp.ClientSession() as s, s.ws_connect(local(srv) + "/view/ws") as ws:
                return await frames(ws, 4)

        got = asyncio.run(run())
        assert got[-1]["width"] == 320 and got[-1]["line_time_ns"] > 0
    for i in range(3):
        cv2.imwrite(str(tmp_path / f"{i:03d}.png"), np.full((48, 64, 3), 40 * i, np.uint8))
    with open_view(open_camera(f"file:{tmp_path}?fps=10"), paced=False) as running:
        assert running.view.controls.describe() == {}
        assert isinstance(running.view.controls, NoControls)


def test_rollcam_view_command_prints_the_page_and_stops():
    cmd = [sys.executable, "-m", "rollcam.host.cli", "view", "emu:imx219?size=320x240&scene=flat",
           "--http", "0.0.0.0:0", "--duration", "1"]
    t0 = time.monotonic()
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "live view:" in done.stdout and "?token=" in done.stdout and "token required" in done.stdout
    assert time.monotonic() - t0 < 120


@pytest.mark.parametrize("faults, whole", [("disconnect=3", 3), ("seed=1,cut=100%", 0)])
def test_a_page_sees_the_camera_go_away_as_the_mjpeg_streams_do(faults, whole):
    # disconnect=N: N whole frames, then the socket closes; a cut frame never arrives whole: it closes at once
    cam = camera()
    srv = MjpegServer(cam, "127.0.0.1", 0, faults=faults)
    lv = LiveView(srv, CameraControls(cam))

    async def run() -> tuple[int, Any]:
        async with aiohttp.ClientSession() as s, s.ws_connect(local(srv) + "/view/ws") as ws:
            n = 0
            async for msg in ws:
                n += msg.type == aiohttp.WSMsgType.BINARY
            return n, ws.close_code

    with srv, lv:
        n, code = asyncio.run(asyncio.wait_for(run(), 60))
        # the page reconnects (as its script does) and is served as before (every frame is cut under cut=100%)
        again = asyncio.run(asyncio.wait_for(frames_after_replug(srv), 60)) if whole else 1
    assert (n, code) == (whole, aiohttp.WSCloseCode.GOING_AWAY)
    assert again == 1


async def frames_after_replug(srv: MjpegServer) -> int:
    await asyncio.sleep(0.6)  # past the REPLUG_S the camera stays away
    async with aiohttp.ClientSession() as s, s.ws_connect(local(srv) + "/view/ws") as ws:
        return len(await frames(ws, 1))
