"""`rollcam bench view`: what the live view costs an emulated 1080p30 device, and the page's update rate.

One run, phases on the same streaming camera (imx219 1920x1080 30 fps RS, street): an MJPEG reader alone (the
encode is paid there already); the reader plus a live page as a Python WebSocket client (it parses every
header: the server's whole cost of a page, no browser competing for the CPU); and, when Debian's chromium and
Selenium are installed, the reader plus a headless Chromium page drawing every frame it is sent with its
overlays on. Figures: the device's delivered frame rate and skipped frames in each phase (ratios within one
run, so other load on the machine cancels), the page's update rate, and the cost per frame of the
overlay/metadata path: the frame tap on the device's thread and the message build on the event loop (the
overlays themselves are drawn in the browser). A browser on the same machine competes for its cores: its
phase's device rate is reported, not held to the target.
"""

from __future__ import annotations

import asyncio
import json
import shutil
import struct
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

from rollcam.common.lifecycle import Deadline, Worker

FPS_RATIO_TARGET = 0.95  # the device with a page watching keeps >= 95% of its frame rate without one
TAP_US_TARGET = 500.0  # device-thread cost per frame (1.5% of a 33 ms frame)
MESSAGE_US_TARGET = 2000.0  # event-loop cost per page message
PAGE_FPS_TARGET = 0.9  # the page updates at >= 90% of the device's delivered rate


def _drain_mjpeg(url: str, stop: threading.Event) -> None:
    """Read the MJPEG stream and throw it away (so the server encodes, as for a program watching) until ``stop``
    is set or the stream ends."""
    with urllib.request.urlopen(url, timeout=10) as r:
        while not stop.is_set() and r.read(65536):
            pass


def _device_phase(cam: Any, pump: Any, seconds: float) -> dict[str, float]:
    f0, s0, t0 = pump.stats.frames, cam.stats.skipped, time.monotonic()
    time.sleep(seconds)
    dt = time.monotonic() - t0
    return {"device_fps": round((pump.stats.frames - f0) / dt, 2), "skipped": cam.stats.skipped - s0,
            "seconds": round(dt, 2)}


def _python_page(ws_url: str, seconds: float, result: dict[str, Any]) -> None:
    import aiohttp

    async def run() -> None:
        async with aiohttp.ClientSession() as s, s.ws_connect(ws_url, max_msg_size=0) as ws:
            n, t0 = 0, time.monotonic()
            async for msg in ws:
                if msg.type == aiohttp.WSMsgType.BINARY:
                    k = struct.unpack(">I", msg.data[:4])[0]
                    json.loads(msg.data[4:4 + k])
                    n += 1
                if time.monotonic() - t0 >= seconds:
                    break
            result["page_fps"] = round(n / (time.monotonic() - t0), 2)

    asyncio.run(run())


def _chromium_page(url: str, seconds: float, profile: Path, result: dict[str, Any]) -> None:
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = shutil.which("chromium") or "/usr/bin/chromium"
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--disable-dev-shm-usage", f"--user-data-dir={profile}", "--window-size=1400,900"):
        opts.add_argument(flag)
    driver = webdriver.Chrome(options=opts, service=Service(shutil.which("chromedriver")))
    try:
        driver.get(url)
        deadline = Deadline(60)
        while driver.execute_script("return window.rollcamView ? rollcamView.stats.drawn : 0") < 3:
            if deadline.expired:
                raise TimeoutError("the page drew no frame in 60 s")
            time.sleep(0.2)
        d0, t0 = driver.execute_script("return rollcamView.stats.drawn"), time.monotonic()
        time.sleep(seconds)
        d1, dt = driver.execute_script("return rollcamView.stats.drawn"), time.monotonic() - t0
        result["page_fps"] = round((d1 - d0) / dt, 2)
        result["page_skipped_here"] = driver.execute_script("return rollcamView.stats.skippedHere")
    finally:
        driver.quit()


def chromium_available() -> bool:
    """Debian's chromium and chromedriver and the selenium package are all here."""
    try:
        import selenium  # noqa: F401
    except ImportError:
        return False
    return bool(shutil.which("chromium") and shutil.which("chromedriver"))


def run_view_bench(seconds: float = 10.0, size: tuple[int, int] = (1920, 1080), fps: float = 30.0,
                   browser: bool | None = None, out_dir: str | Path = ".", say: Any = print) -> dict[str, Any]:
    """Both phases; the document with the figures and the targets."""
    from rollcam.emu.http.mjpeg import MjpegServer
    from rollcam.emu.http.view import LiveView
    from rollcam.emu.http.view_controls import CameraControls
    from rollcam.emu.pump import FramePump
    from rollcam.firmware.camera import FirmwareCamera

    use_browser = chromium_available() if browser is None else browser
    cam = FirmwareCamera("imx219", size=size, fps=fps, scene={"scene": "street", "speed": "fast"})
    pump = FramePump(cam, bands=1, name="rollcam-bench-view")
    server = MjpegServer(cam, pump=pump)
    view = LiveView(server, CameraControls(cam))
    phases: dict[str, dict[str, Any]] = {}
    with server, view, tempfile.TemporaryDirectory() as profile:
        pump.start()
        stop = threading.Event()
        reader = Worker(_drain_mjpeg, server.url, stop, name="bench-view-mjpeg", stop_event=stop).start()
        say(f"warming up {size[0]}x{size[1]} at {fps:g} fps")
        time.sleep(min(seconds, 3.0))
        say("MJPEG reader alone")
        phases["mjpeg_alone"] = _device_phase(cam, pump, seconds)
        ws_url = server.http.base_url.replace("http", "ws", 1) + "/view/ws"
        pages: list[tuple[str, tuple[Any, ...], float]] = [("python_page", (_python_page, ws_url), 1.0)]
        if use_browser:
            pages.append(("chromium_page", (_chromium_page, view.url, Path(profile)), 4.0))
        for name, (fn, *args), settle_s in pages:
            say(f"with a live page: {name}")
            page: dict[str, Any] = {}
            worker = Worker(fn, *args[:1], seconds + settle_s + 2, *args[1:], page, name=f"bench-view-{name}",
                            join_timeout_s=120).start()
            time.sleep(settle_s)  # the page connects (a browser takes longer to start)
            phases[name] = {**_device_phase(cam, pump, seconds)}
            worker.close()  # joined; what failed in the page is raised
            phases[name].update(page)
        reader.close()
        tap, vs = view.tap.stats, view.stats
    return _document(phases, tap.tap_ns / max(tap.frames, 1) / 1e3, vs.message_ns / max(vs.messages, 1) / 1e3,
                     {"size": list(size), "fps": fps, "seconds": seconds, "browser": use_browser})


def _document(phases: dict[str, dict[str, Any]], tap_us: float, msg_us: float, config: dict[str, Any]
              ) -> dict[str, Any]:
    alone = phases["mjpeg_alone"]["device_fps"] or 1e-9
    ratio = phases["python_page"]["device_fps"] / alone
    targets = {
        "device_fps_ratio_with_page": {"value": round(ratio, 3), "op": ">=", "limit": FPS_RATIO_TARGET,
                                       "pass": ratio >= FPS_RATIO_TARGET},
        "tap_us_per_frame": {"value": round(tap_us, 1), "op": "<=", "limit": TAP_US_TARGET,
                             "pass": tap_us <= TAP_US_TARGET},
        "message_us_per_frame": {"value": round(msg_us, 1), "op": "<=", "limit": MESSAGE_US_TARGET,
                                 "pass": msg_us <= MESSAGE_US_TARGET}}
    shown = phases.get("chromium_page", phases["python_page"])
    page_ratio = shown.get("page_fps", 0.0) / (shown["device_fps"] or 1e-9)
    targets["page_fps_ratio"] = {"value": round(page_ratio, 3), "op": ">=", "limit": PAGE_FPS_TARGET,
                                 "pass": page_ratio >= PAGE_FPS_TARGET}
    if "chromium_page" in phases:  # the browser shares this machine's cores with the device: shown, not a target
        phases["chromium_page"]["device_fps_ratio"] = round(phases["chromium_page"]["device_fps"] / alone, 3)
    return {"config": config, **phases, "tap_us_per_frame": round(tap_us, 1),
            "message_us_per_frame": round(msg_us, 1), "targets": targets}


def format_report(doc: dict[str, Any]) -> str:
    """The figures as a few lines of text."""
    c = doc["config"]
    lines = [f"live view at {c['size'][0]}x{c['size'][1]} {c['fps']:g} fps, {c['seconds']:g} s a phase"]
    for name in ("mjpeg_alone", "python_page", "chromium_page"):
        if name in doc:
            p = doc[name]
            page = f", page {p['page_fps']} fps" if "page_fps" in p else ""
            lines.append(f"  {name:>13}: device {p['device_fps']} fps ({p['skipped']} skipped){page}")
    lines.append(f"  per frame: {doc['tap_us_per_frame']} us on the device thread (tap), "
                 f"{doc['message_us_per_frame']} us on the event loop (message); overlays are drawn in the browser")
    return "\n".join(lines)
