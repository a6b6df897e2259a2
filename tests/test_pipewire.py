"""rollcam's camera as a PipeWire Video/Source node (rollcam.host.servers.pipewire), on Debian's pipewire 0.3 and
wireplumber started headless by the test in a private runtime folder, read by real PipeWire clients: pw-dump sees the
node and its formats, GStreamer's pipewiresrc (gstreamer1.0-pipewire) receives frames byte for byte the emulator's."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from interrupts import interrupt
from rollcam.common.errors import ConfigError, DeviceError
from rollcam.host import open_camera
from rollcam.host.servers.pipewire import PROGRAMS, PipeWireCamera, find_node, pw_objects

STILL = "emu:imx219?size=320x240&scene=street&speed=static&lamps=off&noise=off&exposure_us=5000&format=YUYV"
"""A camera whose every frame is the same picture, so any frame PipeWire hands on compares with frame 0."""

pytestmark = pytest.mark.skipif(any(shutil.which(p) is None for p in [*PROGRAMS, "gst-launch-1.0"]),
                                reason="needs pipewire, wireplumber, dbus-daemon and gstreamer1.0-pipewire (apt)")


@pytest.fixture(scope="module")
def camera(tmp_path_factory):
    with PipeWireCamera(STILL, tmp_path_factory.mktemp("pw") / "run", name="rollcam-test") as cam:
        yield cam


def test_pw_dump_sees_a_video_source_with_the_devices_formats(camera):
    node = camera.node()
    props = node["info"]["props"]
    assert (props["media.class"], props["node.description"]) == ("Video/Source", "rollcam imx219")
    formats = node["info"]["params"]["EnumFormat"]
    assert any(f.get("format") == "YUY2" for f in formats), formats


def test_pipewiresrc_receives_the_emulators_frames(camera, tmp_path):
    out = tmp_path / "frames.yuy2"
    p = subprocess.run(["gst-launch-1.0", "-q", "pipewiresrc", "target-object=rollcam-test", "num-buffers=3", "!",
                        "video/x-raw,format=YUY2,width=320,height=240", "!", "filesink", f"location={out}"],
                       env=camera.env, capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr[-2000:]
    with open_camera(STILL) as ref:
        want = ref.read().data.tobytes()
    got = out.read_bytes()
    assert len(got) == 3 * len(want) == 3 * 320 * 240 * 2
    for i in range(3):
        frame = np.frombuffer(got[i * len(want):(i + 1) * len(want)], np.uint8)
        assert frame.tobytes() == want, f"frame {i}: {np.count_nonzero(frame != np.frombuffer(want, np.uint8))} differ"


def test_the_node_goes_when_the_camera_closes(tmp_path):
    cam = PipeWireCamera("emu:imx219?size=160x120", tmp_path / "run", name="rollcam-short")
    env = cam.env
    assert find_node(pw_objects(env), "rollcam-short") is not None
    cam.close()
    cam.close()  # harmless twice
    with pytest.raises(DeviceError, match="pw-dump failed"):  # no daemon left to ask
        pw_objects(env)


@pytest.mark.parametrize(("source", "name", "message"), [
    ("imx999", "cam", "imx999"),
    ("imx219", "two words", "node name 'two words'"),
])
def test_bad_input_is_one_config_error(tmp_path, source, name, message):
    with pytest.raises(ConfigError, match=message):
        PipeWireCamera(source, tmp_path / "run", name=name)


def test_rollcam_pipewire_holds_the_node_until_ctrl_c(tmp_path):
    """The CLI prints the node when it is up; pw-dump finds it there; Ctrl-C ends it (130) and takes the daemons."""
    runtime = tmp_path / "run"
    proc = subprocess.Popen([str(Path(sys.executable).with_name("rollcam")), "pipewire", "emu:imx219?size=160x120",
                             "--name", "rollcam-cli", "--runtime-dir", str(runtime)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = json.loads(proc.stdout.readline())
        assert (line["node"], line["XDG_RUNTIME_DIR"]) == ("rollcam-cli", str(runtime))
        env = {**os.environ, "XDG_RUNTIME_DIR": str(runtime)}
        assert find_node(pw_objects(env), "rollcam-cli")["id"] == line["id"]
        interrupt(proc, timeout_s=60)
        assert proc.returncode == 130
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    with pytest.raises(DeviceError):
        pw_objects(env)


def test_rollcam_pipewire_bad_name_is_exit_2(tmp_path):
    p = subprocess.run([str(Path(sys.executable).with_name("rollcam")), "pipewire", "--name", "a b",
                        "--runtime-dir", str(tmp_path / "run")], capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and p.stderr.startswith("rollcam: error: PipeWire node name 'a b'"), p.stderr
    assert len(p.stderr.strip().splitlines()) == 1
