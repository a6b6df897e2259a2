"""rollcam's labgrid resource and driver (rollcam.host.integrations.labgrid) under labgrid itself: its pytest plugin
runs the example environment and test of docs/labgrid, its Environment loads environment files, and the driver's frames
are compared with the emulator's own, in process (exact), over HTTP (within JPEG's tolerance) and through a real
gst-launch-1.0 (exact)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from programs import need
from rollcam.common.errors import ConfigError
from rollcam.firmware.camera import FirmwareCamera, FramePlan
from rollcam.host import open_camera
from rollcam.sim.codecs import preview_frame

labgrid = pytest.importorskip("labgrid")

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "docs" / "labgrid"
JPEG = {"mean": 4.0, "p99": 32.0}  # as tests/test_one_picture.py: a JPEG decode against the picture it encodes


def environment(tmp_path: Path, resource: str) -> labgrid.Environment:
    """A labgrid Environment of one target whose RollcamCamera resource is the YAML flow mapping ``resource``."""
    path = tmp_path / "env.yaml"
    path.write_text(textwrap.dedent(f"""\
        targets:
          main:
            resources:
              RollcamCamera: {resource}
            drivers:
              RollcamCameraDriver: {{}}
        imports: [rollcam.host.integrations.labgrid]
        """))
    return labgrid.Environment(str(path))


@pytest.fixture
def env(tmp_path):
    made: list[labgrid.Environment] = []

    def make(resource: str) -> labgrid.Environment:
        made.append(environment(tmp_path, resource))
        return made[-1]

    yield make
    for e in made:
        e.cleanup()


def test_example_environment_under_labgrids_pytest_plugin():
    """labgrid's own pytest plugin (``--lg-env``, its ``target`` fixture) runs docs/labgrid's example test."""
    p = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--lg-env",
                        str(EXAMPLE / "rollcam-env.yaml"), str(EXAMPLE / "test_rollcam_camera.py")],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0 and "3 passed" in p.stdout, p.stdout[-3000:] + p.stderr[-2000:]


def test_without_lg_env_the_example_is_skipped_not_failed():
    """Without an environment file labgrid's ``target`` fixture skips: the example never runs on no camera."""
    p = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                        str(EXAMPLE / "test_rollcam_camera.py")], cwd=ROOT, capture_output=True, text=True,
                       timeout=300, env={k: v for k, v in os.environ.items() if k != "LG_ENV"})
    assert p.returncode == 0 and "3 skipped" in p.stdout, p.stdout[-3000:]


def test_driver_frames_equal_the_emulators_for_the_same_seed(env):
    target = env("{source: imx219, options: {scene: street, seed: 11, size: 160x120, speed: fast}}").get_target()
    driver = target.get_driver("VideoProtocol")
    assert type(driver).__name__ == "RollcamCameraDriver"
    got = driver.frames(3)
    with open_camera("emu:imx219?scene=street&seed=11&size=160x120&speed=fast") as ref:
        want = [ref.read() for _ in range(3)]
    for g, w in zip(got, want, strict=True):
        assert g.sequence == w.sequence and np.array_equal(g.data, w.data)
        assert g.objects and [o.box_rs for o in g.objects] == [o.box_rs for o in w.objects]  # with its truth
    other = env("{source: imx219, options: {scene: street, seed: 12, size: 160x120, speed: fast}}").get_target()
    assert not np.array_equal(other.get_driver("VideoProtocol").read().data, want[0].data)


def test_http_transport_serves_the_emulators_picture(env):
    """``transport: http`` starts the emulator's MJPEG server; the driver reads it as a client, and each part is the
    emulator's picture of that sequence number and time within JPEG's tolerance."""
    driver = env("{source: 'emu:imx219?scene=street&seed=4&noise=off', options: {size: 320x240}, "
                 "transport: http}").get_target().get_driver("VideoProtocol")
    assert driver.url.startswith("http://127.0.0.1:")
    assert driver.get_qualities()[1][0][1].startswith("image/jpeg,width=320,height=240,framerate=")
    ref = FirmwareCamera(driver.camera.spec, clock=lambda: 0)
    for frame in driver.frames(2):
        want = preview_frame(ref.render(FramePlan(frame.sequence, ref.schedule(frame.timestamp_ns, frame.sequence))))
        d = np.abs(frame.data.astype(np.int16) - want.astype(np.int16))
        assert d.mean() <= JPEG["mean"] and np.percentile(d, 99) <= JPEG["p99"], (frame.sequence, d.mean())


def test_stream_through_gst_launch_is_exact(env, tmp_path):
    """VideoProtocol's ``stream()``: a real gst-launch-1.0 (fdsrc ! rawvideoparse ! filesink) writes the frames it
    was sent, byte for byte the emulator's, after a control given in labgrid's ``name=value`` form."""
    need("gst-launch-1.0")
    driver = env("{source: imx219, options: {scene: street, seed: 5, size: 100x60, format: YUYV}}"
                 ).get_target().get_driver("VideoProtocol")
    assert dict(driver.get_qualities()[1])["native"].startswith("video/x-raw,format=YUY2,width=100,height=60,")
    out = tmp_path / "video.yuyv"
    assert driver.stream("native", "exposure=2000", sink=f"filesink location={out}", frames=3, timeout_s=60) == 0
    with open_camera("emu:imx219?scene=street&seed=5&size=100x60&format=YUYV") as ref:
        ref.device.set_control("exposure", 2000)
        want = b"".join(ref.read().data.tobytes() for _ in range(3))
    assert len(want) == 3 * 100 * 60 * 2 and out.read_bytes() == want


def test_faults_and_controls_through_the_driver(env):
    """The resource's fault plan is the emu: URI's: the same frames dropped and flagged, counted in fault_stats."""
    driver = env("{source: imx219, options: {scene: flat, level: 0.5, size: 64x48}, faults: 'drop=25%,error=25%,"
                 "seed=3'}").get_target().get_driver("VideoProtocol")
    frames = driver.frames(5)
    assert [f.sequence for f in frames] == [0, 2, 3, 5, 6]
    assert [bool(f.meta.get("error")) for f in frames] == [False, True, False, True, False]
    assert (driver.fault_stats.dropped, driver.fault_stats.errors) == (2, 2)
    gain = driver.controls()["analogue_gain"]
    assert driver.set_control("analogue_gain", gain["max"] + 1) == gain["max"]  # clamped, as V4L2 does
    assert driver.get_control("analogue_gain") == gain["max"]


@pytest.mark.parametrize(("resource", "message"), [
    ("{source: imx999}", "imx999"),
    ("{source: imx219, transport: usb}", "transport 'usb' is not one of ['emu', 'http']"),
    ("{source: imx219, options: {size: 7x}}", "size"),
    ("{source: imx219, faults: 'drop=often'}", "drop"),
])
def test_a_bad_resource_is_one_config_error_when_the_environment_loads(env, resource, message):
    with pytest.raises(ConfigError, match=None) as err:
        env(resource).get_target()
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_bad_stream_request_names_the_problem(env):
    driver = env("{source: imx219, options: {size: 64x48}}").get_target().get_driver("VideoProtocol")
    with pytest.raises(ConfigError, match="unknown video quality 'high'"):
        driver.stream("high")
    with pytest.raises(ConfigError, match="control 'exposure' is not NAME=INTEGER"):
        driver.stream(controls="exposure")
    bayer = env("{source: imx219, options: {size: 64x48, format: RGGB}}").get_target().get_driver("VideoProtocol")
    with pytest.raises(ConfigError, match="sends packed raw video"):
        bayer.stream(frames=1)


def test_without_labgrid_the_module_names_the_extra():
    code = "import sys; sys.modules['labgrid'] = None\nimport rollcam.host.integrations.labgrid"
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode != 0 and "rollcam[labgrid]" in p.stderr, p.stderr[-2000:]
