"""A web page's camera: Debian's Chromium, headless and driven by Selenium (Debian's chromedriver given
explicitly), under ``rollcam run``'s preload library. The page lists the emulated camera, opens it with
``getUserMedia``, draws the stream into a canvas, and the drawn picture is the emulator's frame within the
browser's own conversion error.

Chromium picks its own format (YU12, planar 4:2:0: the one that came out green before the chroma planes were
filled) and converts it with libyuv (BT.601 limited range, as G_FMT says): measured against the reference picture
(OpenCV's conversion of the same bytes) it is off by at most 1 level, so ``BROWSER`` allows a mean |difference|
of 0.5 and a maximum of 2 per channel. The device shows a still street without temporal noise, so every frame is
the same picture (``test_one_picture`` checks that premise) and the reference is a second camera's frame 0.
"""

from __future__ import annotations

import base64
import functools
import http.server
import threading
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest
from rollcam.emu.preload import LIBRARY_NAME
from rollcam.emu.preload import __file__ as preload_init
from rollcam.firmware.camera import FirmwareCamera, FramePlan
from rollcam.firmware.imaging import encode
from rollcam.host.servers.devnodes import program_environment, serving
from rollcam.sim.codecs import preview_frame

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed (pip install selenium)")
LIB = Path(preload_init).with_name(LIBRARY_NAME)
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not (Path(CHROMIUM).exists() and Path(CHROMEDRIVER).exists()),
                       reason="needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"),
    pytest.mark.skipif(not LIB.is_file(), reason=f"{LIB} not built (pip install -e . with a C compiler)"),
]

STILL = "emu:imx219?size=640x480&scene=street&speed=static&lamps=off&noise=off&exposure_us=5000"
BROWSER_FLAGS = (
    "--headless=new",
    "--no-sandbox",  # Chromium refuses to run as root with its sandbox (CI runs as root)
    "--use-fake-ui-for-media-stream",  # grant the camera permission without a prompt nobody can click
    "--disable-gpu", "--disable-dev-shm-usage", "--no-first-run", "--disable-background-networking",
)
BROWSER = {"mean": 0.5, "max": 2}
PAGE = """<!doctype html>
<html><body><video id="v" autoplay muted playsinline></video><canvas id="c" width="640" height="480"></canvas>
<script>
window.result = {state: "waiting"};
(async () => {
  try {
    const stream = await navigator.mediaDevices.getUserMedia({video: {width: {exact: 640}, height: {exact: 480}}});
    const track = stream.getVideoTracks()[0];
    window.result.label = track.label;
    window.result.settings = track.getSettings();
    window.result.devices = (await navigator.mediaDevices.enumerateDevices()).map(d => [d.kind, d.label]);
    const v = document.getElementById("v");
    v.srcObject = stream;
    await v.play();
    for (let i = 0; i < 3; i++) await new Promise(done => v.requestVideoFrameCallback(done));
    const c = document.getElementById("c");
    c.getContext("2d").drawImage(v, 0, 0, 640, 480);
    window.result.png = c.toDataURL("image/png");
    window.result.state = "drawn";
  } catch (e) {
    window.result.state = "error";
    window.result.error = String(e);
  }
})();
</script></body></html>
"""


@pytest.fixture
def page_url(tmp_path: Path) -> Iterator[str]:
    """The page on a local HTTP server (getUserMedia needs a secure context: localhost is one)."""
    (tmp_path / "index.html").write_text(PAGE)
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(tmp_path))
    with http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler) as httpd:
        thread = threading.Thread(target=httpd.serve_forever, daemon=True)
        thread.start()
        yield f"http://127.0.0.1:{httpd.server_port}/index.html"
        httpd.shutdown()
        thread.join(10)


def test_chromium_lists_the_camera_and_draws_the_emulators_picture(page_url, tmp_path):
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.support.wait import WebDriverWait

    with serving([("/dev/video0", STILL)]) as server:
        opts = webdriver.ChromeOptions()
        opts.binary_location = CHROMIUM
        for flag in (*BROWSER_FLAGS, f"--user-data-dir={tmp_path / 'profile'}"):
            opts.add_argument(flag)
        # chromedriver starts Chromium with its own environment: the preload library reaches every process
        driver = webdriver.Chrome(options=opts, service=Service(CHROMEDRIVER, env=program_environment(server)))
        try:
            driver.get(page_url)
            result = WebDriverWait(driver, 90, poll_frequency=0.2).until(
                lambda d: (r := d.execute_script("return window.result"))["state"] != "waiting" and r)
        finally:
            driver.quit()
        spec = server.nodes["/dev/video0"].driver.camera.spec
    png = result.pop("png", None)
    assert result["state"] == "drawn", result
    assert result["devices"] == [["videoinput", "rollcam imx219 emulator"]]
    assert result["label"] == "rollcam imx219 emulator"
    assert (result["settings"]["width"], result["settings"]["height"]) == (640, 480)
    drawn = cv2.imdecode(np.frombuffer(base64.b64decode(png.split(",", 1)[1]), np.uint8), cv2.IMREAD_COLOR)
    camera = FirmwareCamera(spec, clock=lambda: 0)
    want = preview_frame(encode(camera.render(FramePlan(0, camera.schedule(0))), spec))
    d = np.abs(drawn.astype(np.int16) - want).reshape(-1, 3)
    assert (d.mean(axis=0) <= BROWSER["mean"]).all() and (d.max(axis=0) <= BROWSER["max"]).all(), (
        f"Chromium drew {spec.pixel_format} off by mean {d.mean(axis=0).round(2)}, max {d.max(axis=0)} (B, G, R)")
