"""The picamera2 stand-in: unmodified picamera2-style scripts in a child process, and through the fixture.

The scripts in tests/picamera2_examples are written as picamera2's own examples are, knowing nothing of
rollcam; each runs with only ``rollcam.host.standin_env`` (the stand-ins on PYTHONPATH, the cameras named)
and prints one JSON line that the test checks.
"""

from __future__ import annotations

import ast
import itertools
import json
import re
import subprocess
import sys
import time
from fnmatch import fnmatch
from pathlib import Path

import cv2
import pytest
from rollcam.host import shims_path, standin_env

pytest_plugins = ["pytester"]

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = Path(__file__).parent / "picamera2_examples"


def run_script(name: str, *args: str, sources: tuple[str, ...] = ("imx219",)) -> object:
    """Run an example with the stand-ins on its path; its JSON output."""
    done = subprocess.run([sys.executable, str(EXAMPLES / name), *args], env=standin_env(sources), cwd=EXAMPLES,
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def check_intervals(stamps: list[int], period_ns: int, tolerance_ns: int = 1) -> list[int]:
    """Frame intervals as whole numbers of frame periods (a late frame is skipped, never shifted)."""
    counts = []
    for a, b in itertools.pairwise(stamps):
        k = round((b - a) / period_ns)
        assert k >= 1 and abs((b - a) - k * period_ns) <= k * tolerance_ns + 1, (a, b, period_ns)
        counts.append(k)
    return counts


def test_capture_array_loop_and_capture_file(tmp_path):
    path = tmp_path / "still.jpg"
    out = run_script("capture_loop.py", str(path))
    assert out["model"] == "imx219"
    assert out["shapes"] == [[240, 320, 4]] * 6
    assert all(a == 255 for a in out["alphas"])
    assert all(20 < m < 235 for m in out["means"])  # the street scene, not black, not blown out
    assert out["config"]["stride"] == 320 * 4 and out["config"]["size"] == [320, 240]
    image = cv2.imread(str(path))
    assert image is not None and image.shape == (240, 320, 3)
    assert out["file_exposure"] == 9999  # the source's default exposure (10 ms in whole lines)


def test_capture_request_metadata_and_lores():
    frames = run_script("metadata_lores.py")
    assert all(f["main"] == [240, 320, 3] and f["lores"] == [180, 160] for f in frames)
    assert all(isinstance(f["ts"], int) for f in frames)
    period = frames[0]["period_ns"]
    assert frames[0]["duration"] == round(period / 1000) == 50000  # FrameRate 20
    assert sum(check_intervals([f["ts"] for f in frames], period)) >= len(frames) - 1
    assert all(abs(f["line_ns"] - 3448e9 / 182.4e6) <= 1 and f["readout"] == "top_to_bottom" for f in frames)
    assert all(f["black"] == [4096] * 4 and f["gain"] == 1.0 and f["digital"] == 1.0 for f in frames)
    assert all(30 < f["y_mean"] < 220 for f in frames)


def test_set_controls_exposure_darkens_from_its_frame():
    records = run_script("exposure_change.py")
    long = [r for r in records if r["phase"] == "long"]
    assert all(r["exposure"] == pytest.approx(20000, abs=20) for r in long)
    short = [r for r in records if r["exposure"] < 3000]
    assert short and all(r["phase"] == "short" for r in short)
    # Applied on a frame boundary: at most the one frame already queued and the one exposing come before it.
    first = records.index(short[0])
    assert first - len(long) <= 2
    assert records[first:] == short  # and it stays
    assert max(r["mean"] for r in short) < 0.6 * min(r["mean"] for r in long)
    assert {r["duration"] for r in records} == {100000}
    check_intervals([r["ts"] for r in records], 100_000_000, tolerance_ns=500)  # FrameDuration is in whole us


def test_raw_streams_as_picamera2_gives_them():
    out = run_script("raw_capture.py")
    u = out["unpacked"]
    assert u["shape"] == [480, 1280] and u["dtype"] == "uint8"  # two bytes per sample, little-endian
    assert 64 < u["mean"] < u["max"] <= 1023  # 10-bit samples in the low bits, above the black level
    assert u["stream"]["format"] == "SRGGB10" and u["stream"]["stride"] == 1280
    p = out["packed"]
    assert p["mode"] == "SRGGB10_CSI2P" and p["stream"] == "SRGGB10_CSI2P" and p["size"] == [640, 480]
    assert p["shape"] == [480, 800] and p["dtype"] == "uint8"  # 5 bytes per 4 pixels
    assert isinstance(p["timestamp"], int)


# ---------------------------------------------------------------------------------------------- in process
def test_description_of_each_pi_sensor(rollcam_picamera2):
    picamera2 = rollcam_picamera2("imx219", "emu:imx477?scene=flat", "imx708")
    info = picamera2.Picamera2.global_camera_info()
    assert [c["Model"] for c in info] == ["imx219", "imx477", "imx708"]
    with picamera2.Picamera2(1) as cam:
        assert cam.camera_properties["PixelArraySize"] == (4056, 3040)
        modes = cam.sensor_modes
        assert {str(m["format"]) for m in modes} == {"SRGGB12_CSI2P", "SRGGB10_CSI2P"}
        assert modes[0]["bit_depth"] == 12 and modes[0]["unpacked"] == "SRGGB12"
        assert all(m["fps"] > 0 and m["exposure_limits"][0] < m["exposure_limits"][1] for m in modes)
        assert cam.sensor_resolution == (4056, 3040) and cam.sensor_format == "SRGGB12_CSI2P"
        lo, hi, _ = cam.camera_controls["AnalogueGain"]
        assert (lo, hi) == (1.0, 22.26)
    with picamera2.Picamera2(2) as cam:
        assert "AfMode" in cam.camera_controls and cam.camera_properties["Model"] == "imx708"


def test_mode_selection_follows_libcamera(rollcam_picamera2):
    picamera2 = rollcam_picamera2()
    with picamera2.Picamera2() as cam:
        for main, raw_size in (((640, 480), (640, 480)), ((1280, 720), (1920, 1080)), ((1640, 1232), (1640, 1232))):
            cam.configure(cam.create_preview_configuration(main={"size": main}))
            assert cam.camera_configuration()["raw"]["size"] == raw_size
        cam.configure(cam.create_still_configuration(sensor={"output_size": (640, 480), "bit_depth": 8}))
        assert cam.camera_configuration()["raw"]["format"] == "SRGGB8"
        cam.configure(cam.create_preview_configuration(transform=__import__("libcamera").Transform(hflip=1)))
        assert cam.camera_configuration()["raw"]["format"] == "SGRBG10_CSI2P"  # the flip moves the Bayer order


def test_controls_go_through_the_device(rollcam_picamera2):
    picamera2 = rollcam_picamera2()
    with picamera2.Picamera2() as cam:
        cam.configure(cam.create_video_configuration(main={"size": (320, 240)}, controls={"FrameRate": 10}))
        cam.rollcam_device.controls()  # the same device the serial, V4L2 and UVC doors program
        cam._cam.apply({"ExposureTime": 5000, "AnalogueGain": 4.0})
        dev = cam.rollcam_device
        line = dev.spec.settings.timing.line_offset_ns(1)
        assert dev.get_control("exposure") == round(5_000_000 / line)
        assert dev.state.gain == pytest.approx(4.0, rel=0.01)
        assert dev.frame_interval_ns == pytest.approx(100_000_000, abs=30_000)  # FrameDurationLimits held
        cam._cam.apply({"ExposureTime": 400_000})  # longer than FrameDurationLimits allow: clamped to the frame
        assert dev.frame_interval_ns == pytest.approx(100_000_000, abs=30_000)
        assert dev.spec.settings.exposure_ns < 100_000_000
        cam._cam.apply({"FrameDurationLimits": (100, 1_000_000)})  # within the limits the frame stretches
        assert 400_000_000 < dev.frame_interval_ns < 401_000_000
        assert dev.spec.settings.exposure_ns == pytest.approx(400_000_000, abs=line)


@pytest.mark.parametrize(("change", "message"), [
    (lambda c: c.update(main={"size": (320, 240), "format": "BGR"}), "Bad format BGR in stream main"),
    (lambda c: c.update(main={"size": (321, 240), "format": "RGB888"}), "width and height should be even"),
    (lambda c: c.update(lores={"size": (800, 600), "format": "YUV420"}), "lores stream dimensions may not exceed"),
    (lambda c: c.update(lores={"size": (160, 120), "format": "RGB888"}), "lores stream must be YUV"),
    (lambda c: c.update(raw={"size": (640, 480), "format": "RGB888"}), "Unrecognised raw format RGB888"),
    (lambda c: c.update(sensor={"size": (640, 480)}), "Unexpected keys"),
    (lambda c: c.update(main={"size": (9000, 240), "format": "RGB888"}), "exceeds the sensor's pixel array"),
])
def test_bad_configurations_are_refused_as_picamera2_does(rollcam_picamera2, change, message):
    picamera2 = rollcam_picamera2()
    with picamera2.Picamera2() as cam:
        config = cam.create_preview_configuration()
        change(config)
        with pytest.raises(RuntimeError, match=message):
            cam.configure(config)


def test_misuse_is_refused(rollcam_picamera2):
    picamera2 = rollcam_picamera2()
    with picamera2.Picamera2() as cam:
        with pytest.raises(TimeoutError, match="not started"):
            cam.capture_array(wait=0.05)  # a capture waits for start(), here not for long
        with pytest.raises(RuntimeError, match="not advertised"):
            cam.set_controls({"ExposureTim": 1000})
        with pytest.raises(ValueError, match="Bad key"):
            cam.create_preview_configuration(main={"sise": (320, 240)})
        with pytest.raises(RuntimeError, match="Camera __init__ sequence did not complete"):
            picamera2.Picamera2(0)  # one process holds a camera at a time, as libcamera's acquire
        with pytest.raises(IndexError):
            picamera2.Picamera2(3)
        with pytest.raises(RuntimeError, match="Invalid field"):
            cam.preview_configuration.mian = {}


def test_frames_in_process_with_callbacks_and_stop_start(rollcam_picamera2):
    picamera2 = rollcam_picamera2("emu:imx219?scene=flat&level=0.3")
    cam = picamera2.Picamera2()
    seen = []

    def mark(request):  # picamera2's pre_callback idiom: draw on the buffer before anyone reads it
        with picamera2.MappedArray(request, "main") as m:
            m.array[:8, :8] = 0
        seen.append(request.get_metadata()["RollcamSequence"])

    cam.pre_callback = mark
    cam.start(cam.create_preview_configuration(main={"size": (320, 240)}, controls={"FrameRate": 10}))
    with pytest.raises(RuntimeError, match="stopped before configuring"):
        cam.configure("preview")
    a = cam.capture_array()
    assert a[:8, :8, :3].max() == 0 and a[20:, 20:, :3].mean() > 20
    job = cam.capture_metadata(wait=False)
    assert isinstance(cam.wait(job, 10)["SensorTimestamp"], int)
    cam.stop()
    cam.start()
    arrays, md = cam.capture_arrays(["main", "raw"])
    assert arrays[1].shape == (480, 800) and md["RollcamSequence"] in seen
    cam.close()
    cam.close()
    assert not cam.is_open


def test_the_fixture_restores_the_import_system(pytester):
    pytester.makepyfile(test_user='''
        import sys

        def test_uses_it(rollcam_picamera2):
            picamera2 = rollcam_picamera2("imx708")
            from picamera2 import Picamera2
            assert picamera2.ROLLCAM_STANDIN
            Picamera2()  # left open on purpose: the fixture closes it

        def test_after():
            assert not any(m == "picamera2" or m.startswith(("picamera2.", "libcamera")) for m in sys.modules)
            assert not any("shims" in p for p in sys.path)
    ''')
    # labgrid's plugin (the labgrid extra) starts a process-wide step logger once: an in-process run leaves it out
    pytester.runpytest("-p", "no:cacheprovider", "-p", "no:labgrid").assert_outcomes(passed=2)


def test_standins_ship_as_package_data():
    line = re.search(r'^"rollcam\.host" = (\[.*?\])', (ROOT / "pyproject.toml").read_text(), re.M)
    assert line is not None, "pyproject.toml ships no package data for rollcam.host"
    patterns = ast.literal_eval(line.group(1))
    shipped = [p.relative_to(ROOT / "host").as_posix() for p in shims_path().rglob("*.py")]
    assert {"shims/picamera2/__init__.py", "shims/libcamera/__init__.py"} <= set(shipped)
    assert all(any(fnmatch(f, pat) for pat in patterns) for f in shipped)
    env = standin_env(["emu:imx477?scene=flat"], {"PYTHONPATH": "/elsewhere"})
    assert env["PYTHONPATH"].split(":") == [str(shims_path()), "/elsewhere"]
    assert env["ROLLCAM_PICAMERA2"] == "emu:imx477?scene=flat"


def test_a_bad_control_value_is_logged_and_the_frames_go_on(rollcam_picamera2, caplog):
    picamera2 = rollcam_picamera2()
    with picamera2.Picamera2() as cam:
        cam.start(cam.create_preview_configuration(main={"size": (320, 240)}, controls={"FrameRate": 10}))
        cam.set_controls({"ExposureTime": "long"})
        first = cam.capture_metadata()["RollcamSequence"]
        assert cam.capture_metadata()["RollcamSequence"] > first
        assert cam.capture_metadata()["ExposureTime"] == 9999
    assert "cannot take 'long'" in caplog.text


def test_a_capture_made_before_start_waits_for_it(rollcam_picamera2):
    # picamera2's examples/frame_server.py starts its capturing thread one line before start().
    picamera2 = rollcam_picamera2()
    with picamera2.Picamera2() as cam:
        cam.configure(cam.create_preview_configuration(main={"size": (320, 240)}, controls={"FrameRate": 30}))
        job = cam.capture_array(wait=False)
        assert not job.done()
        cam.start()
        assert cam.wait(job, 60).shape == (240, 320, 4)
    closed = picamera2.Picamera2()
    job = closed.capture_metadata(wait=False)
    closed.close()
    with pytest.raises(RuntimeError, match="closed"):
        job.get_result(10)


def test_a_flush_many_frames_ahead_releases_the_skipped_requests(rollcam_picamera2):
    # examples/timestamp_capture.py: flush half a second ahead is 15 frames at 30 fps, more than the buffers.
    picamera2 = rollcam_picamera2()
    with picamera2.Picamera2() as cam:
        cam.start(cam.create_preview_configuration(main={"size": (320, 240)}, buffer_count=2,
                                                   controls={"FrameRate": 30}))
        for _ in range(2):
            after = time.monotonic_ns() + 500_000_000
            with cam.captured_request(wait=30, flush=after) as request:
                md = request.get_metadata()
            assert md["SensorTimestamp"] - 1000 * md["ExposureTime"] >= after  # picamera2's test of a flush
        assert cam.capture_request(flush=True, wait=30).release() is None
