"""The live view in a real headless browser (Debian's chromium and chromedriver, driven by Selenium), on a
``rollcam emulate --http --serial`` process: the page loads and updates, overlays toggle, exposure set on the
page changes the picture and reads back on the serial line (and the reverse), a bad value shows an error
while the device keeps streaming, and the snapshot button saves PNG + JSON."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from helpers import wait_for

CHROMIUM, CHROMEDRIVER = shutil.which("chromium") or "/usr/bin/chromium", shutil.which("chromedriver") or ""
webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed (pip install selenium)")
if not (Path(CHROMIUM).exists() and CHROMEDRIVER):
    pytest.skip("needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)",
                allow_module_level=True)
serial = pytest.importorskip("serial")

BROWSER_FLAGS = ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--disable-dev-shm-usage", "--window-size=1400,900")


@pytest.fixture(scope="module")
def emulator() -> Iterator[dict[str, Any]]:
    cmd = [sys.executable, "-m", "rollcam.host.cli", "emulate", "imx219", "--size", "640x480", "--scene", "street",
           "--seed", "3", "--physics", "on", "--noise", "off", "--exposure-us", "2000", "--fps", "15",
           "--http", "127.0.0.1:0", "--serial", "--json", "--duration", "300"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert line, proc.stderr.read()
        yield json.loads(line)
    finally:
        proc.terminate()
        proc.communicate(timeout=30)


@pytest.fixture(scope="module")
def page(emulator: dict[str, Any], tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for flag in BROWSER_FLAGS:
        opts.add_argument(flag)
    opts.add_argument(f"--user-data-dir={tmp_path_factory.mktemp('chromium-profile')}")
    downloads = tmp_path_factory.mktemp("downloads")
    opts.add_experimental_option("prefs", {"download.default_directory": str(downloads),
                                           "download.prompt_for_download": False,
                                           # two files from one click: Chromium asks a person once, this says yes
                                           "profile.default_content_setting_values.automatic_downloads": 1})
    driver = webdriver.Chrome(options=opts, service=Service(CHROMEDRIVER))
    driver.downloads = downloads
    try:
        driver.get(emulator["http"]["view"])
        wait_for(lambda: js(driver, "return rollcamView.stats.drawn") >= 3, 60, "the first frames drawn")
        yield driver
    finally:
        driver.quit()


def js(driver: Any, script: str, *args: Any) -> Any:
    return driver.execute_script(script, *args)


MEAN_LUMA = """const img = rollcamView.image, c = new OffscreenCanvas(64, 48), g = c.getContext('2d');
g.drawImage(img, 0, 0, 64, 48); const d = g.getImageData(0, 0, 64, 48).data; let s = 0;
for (let i = 0; i < d.length; i += 4) s += d[i] + d[i + 1] + d[i + 2]; return s / (d.length / 4) / 3;"""
CANVAS = "return document.getElementById('view').toDataURL('image/png')"


def set_control(driver: Any, name: str, value: str) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    box = driver.find_element(By.ID, f"ctl-{name}")
    box.send_keys(Keys.CONTROL, "a")
    box.send_keys(value, Keys.TAB)  # the change event fires when the field loses focus, as a person does it


def exposure_us(driver: Any) -> float:
    return js(driver, "return rollcamView.meta.exposure_ns") / 1000


def test_page_loads_and_the_image_updates(page):
    from selenium.webdriver.common.by import By

    assert "rollcam" in page.title
    first = js(page, "return rollcamView.meta.seq")
    wait_for(lambda: js(page, "return rollcamView.meta.seq") > first + 3, what="newer frames")
    assert page.find_element(By.ID, "meta-sequence").text.isdigit()
    assert js(page, "return rollcamView.meta.objects.length") > 0  # truth came with the frames
    assert js(page, "return rollcamView.intervals.length") > 2  # the plot has data


def test_toggling_an_overlay_changes_the_picture_and_snapshot_saves_png_and_json(page):
    from selenium.webdriver.common.by import By

    page.find_element(By.ID, "hold").click()
    try:
        time.sleep(0.3)  # a decode in flight finishes
        with_boxes = js(page, CANVAS)
        for box in ("ov-gs", "ov-rs", "ov-ids"):
            page.find_element(By.ID, box).click()
        without = js(page, CANVAS)
        assert without != with_boxes
        for box in ("ov-gs", "ov-rs", "ov-ids"):
            page.find_element(By.ID, box).click()
        assert js(page, CANVAS) == with_boxes  # the same frame redrawn: only the overlay changed
    finally:
        page.find_element(By.ID, "hold").click()
    page.find_element(By.ID, "snapshot").click()
    pngs = wait_for(lambda: list(page.downloads.glob("rollcam-*.png")), what="the snapshot files")
    truth_file = wait_for(lambda: [p for p in page.downloads.glob("rollcam-*.json") if p.stat().st_size > 0],
                          what="the truth file")
    assert pngs[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    truth = json.loads(truth_file[0].read_text())
    assert truth["width"] == 640 and truth["objects"] and pngs[0].stem == truth_file[0].stem


def test_exposure_from_the_page_changes_brightness_and_the_serial_side_reads_it(page, emulator):
    wait_for(lambda: abs(exposure_us(page) - 2000) < 30, what="2 ms exposure")
    dark = js(page, MEAN_LUMA)
    set_control(page, "exposure_us", "8000")
    wait_for(lambda: abs(exposure_us(page) - 8000) < 30, what="8 ms exposure on the stream")
    time.sleep(0.3)
    bright = js(page, MEAN_LUMA)
    assert bright > dark * 1.5, (dark, bright)
    with serial.Serial(emulator["serial"]["path"], timeout=5) as port:
        port.write(b"OPT? exposure_us\n")
        assert abs(float(port.readline()) - 8000) < 30
        port.write(b"OPT exposure_us 3000\n")  # and the reverse: the serial side's change shows on the page
        assert port.readline().startswith(b"OK")
    wait_for(lambda: abs(float(js(page, "return document.getElementById('ctl-exposure_us').value")) - 3000) < 30,
             what="the page's control to follow the serial side")


def test_a_bad_control_value_shows_an_error_and_the_device_keeps_streaming(page):
    from selenium.webdriver.common.by import By

    set_control(page, "exposure_us", "-5")
    error = page.find_element(By.ID, "error")
    wait_for(lambda: error.is_displayed() and "exposure_us" in error.text, what="the error on the page")
    assert "'-5'" in error.text and "must be a number >= 0" in error.text
    seq = js(page, "return rollcamView.meta.seq")
    wait_for(lambda: js(page, "return rollcamView.meta.seq") > seq + 3, what="frames after the error")
