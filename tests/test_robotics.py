"""Robotics recordings (`rollcam capture --format mcap|ros2bag|rosbag1|kalibr`), read back by independent readers.

MCAP through mcap's own reader and mcap_ros2's decoder; ROS 2 and ROS 1 bags through rosbags' AnyReader; a
conversion between them through rosbags' own converter (``python -m rosbags.convert``). Every message is checked
against the emulator's frames of the same URI (rendered again here: the emulator is deterministic): stamps to
the nanosecond, image sizes, encodings and pixels, CameraInfo against the lens, IMU samples against the IMU,
rolling-shutter timing and ground truth against the frame's own.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from interrupts import ctrl_c
from rollcam.common.errors import ConfigError, MissingDependencyError
from rollcam.host import open_camera
from rollcam.host.recording.capture import CaptureInterrupted, capture
from rollcam.host.robotics import KALIBR_TOPICS, OUTPUT, BagWriter
from rollcam.host.robotics.bags import require_libraries

pytest.importorskip("mcap_ros2")
pytest.importorskip("rosbags")

URI = "emu:imx219?size=160x120&ego=pan&imu=on&imu_rate=400&seed=4"
N = 3
CAMERA_TOPICS = {"/cam0/image_raw": "sensor_msgs/msg/Image", "/cam0/camera_info": "sensor_msgs/msg/CameraInfo",
                 "/cam0/rolling_shutter": "rollcam_msgs/msg/RollingShutter",
                 "/cam0/truth": "rollcam_msgs/msg/FrameTruth", "/cam0/line_poses": "rollcam_msgs/msg/LinePoses",
                 "/imu0": "sensor_msgs/msg/Imu"}


@pytest.fixture(scope="module")
def frames():
    with open_camera(URI) as cam:
        return [cam.read() for _ in range(N)]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> dict[str, Path]:
    out = {}
    for fmt in ("mcap", "ros2bag", "rosbag1", "kalibr"):
        folder = tmp_path_factory.mktemp(fmt)
        with open_camera(URI) as cam:
            result = capture(cam, folder, N, fmt=fmt, progress=False)
        assert result.complete and result.recording == folder / OUTPUT[fmt]
        out[fmt] = result.recording
    return out


def _ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _field(msg: Any, name: str) -> Any:
    """A field under ROS 2's name or ROS 1's (CameraInfo's ``K`` is ``k`` in ROS 2)."""
    return getattr(msg, name) if hasattr(msg, name) else getattr(msg, name.upper())


def read_mcap(path: Path) -> list[tuple[str, str, int, Any]]:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        return [(ch.topic, schema.name, msg.log_time, dec) for schema, ch, msg, dec in reader.iter_decoded_messages()]


def read_bag(path: Path) -> list[tuple[str, str, int, Any]]:
    from rosbags.highlevel import AnyReader

    with AnyReader([path]) as reader:
        return [(c.topic, c.msgtype, t, reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages()]


def by_topic(messages: list[tuple[str, str, int, Any]]) -> dict[str, list[tuple[str, int, Any]]]:
    out: dict[str, list[tuple[str, int, Any]]] = {}
    for topic, typ, t, msg in messages:
        out.setdefault(topic, []).append((typ, t, msg))
    return out


def check_recording(messages: list[tuple[str, str, int, Any]], frames: list) -> None:
    """Every message of a full recording against the emulator's frames."""
    topics = by_topic(messages)
    assert {t: v[0][0] for t, v in topics.items()} == CAMERA_TOPICS
    for topic, items in topics.items():
        for _typ, t, msg in items:  # the log time is the header stamp, exactly
            assert t == _ns(msg.header.stamp), topic
    assert all(len(topics[t]) == N for t in CAMERA_TOPICS if t != "/imu0")
    for i, f in enumerate(frames):
        img = topics["/cam0/image_raw"][i][2]
        assert _ns(img.header.stamp) == f.timestamp_ns and img.header.frame_id == "cam0"
        assert (img.height, img.width, img.encoding, img.step) == (120, 160, "bgr8", 480)
        assert np.array_equal(np.frombuffer(bytes(img.data), np.uint8).reshape(120, 160, 3), f.data)

        info = topics["/cam0/camera_info"][i][2]
        fx, fy, cx, cy = f.meta["intrinsics"]
        assert info.distortion_model == "plumb_bob" and list(_field(info, "d")) == [0.0] * 5
        assert list(_field(info, "k")) == [fx, 0, cx, 0, fy, cy, 0, 0, 1]
        assert list(_field(info, "p")) == [fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0]
        assert list(_field(info, "r")) == [1, 0, 0, 0, 1, 0, 0, 0, 1] and (info.width, info.height) == (160, 120)

        rs = topics["/cam0/rolling_shutter"][i][2]
        assert (rs.sequence, rs.shutter, rs.first_line_ns, rs.exposure_ns, rs.line_time_ns, rs.readout, rs.lines) \
            == (f.sequence, "rolling", f.timestamp_ns, f.exposure_ns, f.line_time_ns, "top_to_bottom", 120)
        assert rs.readout_ns == 120 * f.line_time_ns
        assert np.array_equal(np.asarray(rs.line_times_ns), f.row_times_ns)

        truth = topics["/cam0/truth"][i][2]
        assert len(truth.objects) == len(f.objects) > 0
        for o, want in zip(truth.objects, f.objects, strict=True):
            assert (o.id, o.cls, o.visible, o.speed_mps) == (want.id, want.cls, want.visible, want.speed_mps)
            assert o.has_box_gs == (want.box_gs is not None) and o.has_box_rs == (want.box_rs is not None)
            if want.box_gs is not None:
                assert list(o.box_gs) == list(want.box_gs)
            if want.box_rs is not None:
                assert list(o.box_rs) == list(want.box_rs)

        poses = topics["/cam0/line_poses"][i][2]
        k = f.poses
        assert np.array_equal(np.asarray(poses.t_ns), k.t_ns) and len(poses.poses) == 120
        got = np.array([[p.position.x, p.position.y, p.position.z] for p in poses.poses])
        quat = np.array([[p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z] for p in poses.poses])
        assert np.array_equal(got, k.position) and np.array_equal(quat, k.quaternion_wxyz)
        assert np.array_equal(np.array([[v.x, v.y, v.z] for v in poses.angular_velocity]), k.angular_velocity)

    imu = topics["/imu0"]
    t_ns = np.concatenate([f.imu.t_ns for f in frames])
    gyro = np.concatenate([f.imu.gyro for f in frames])
    accel = np.concatenate([f.imu.accel for f in frames])
    assert [t for _, t, _ in imu] == t_ns.tolist() and len(imu) > 3 * N
    assert np.array_equal(np.array([[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z]
                                    for _, _, m in imu]), gyro)
    assert np.array_equal(np.array([[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z]
                                    for _, _, m in imu]), accel)
    assert all(m.orientation_covariance[0] == -1 and m.header.frame_id == "imu0" for _, _, m in imu)


def test_mcap_reads_back_with_mcap_and_its_ros2_decoder(recorded, frames):
    check_recording(read_mcap(recorded["mcap"]), frames)


@pytest.mark.parametrize("fmt", ["ros2bag", "rosbag1"])
def test_bags_read_back_with_rosbags(recorded, frames, fmt):
    check_recording(read_bag(recorded[fmt]), frames)


def test_ros2_bag_with_mcap_storage_reads_back_with_both_readers(tmp_path, frames):
    from rollcam.host.cli import main

    assert main(["capture", URI, "--frames", str(N), "--out", str(tmp_path), "--format", "ros2bag",
                 "--bag-storage", "mcap"]) == 0
    bag = tmp_path / "capture_ros2"
    assert sorted(p.name for p in bag.iterdir()) == ["capture_ros2.mcap", "metadata.yaml"]
    check_recording(read_bag(bag), frames)
    check_recording(read_mcap(bag / "capture_ros2.mcap"), frames)


@pytest.mark.parametrize(("src", "dst"), [("ros2bag", "converted.bag"), ("rosbag1", "converted_ros2")])
def test_rosbags_converts_each_bag_to_the_other_ros(recorded, frames, tmp_path, src, dst):
    out = tmp_path / dst
    proc = subprocess.run([sys.executable, "-m", "rosbags.convert", "--src", str(recorded[src]), "--dst", str(out)],
                          capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr
    check_recording(read_bag(out), frames)


def test_kalibr_bag_holds_exactly_kalibrs_topics(recorded, frames):
    messages = read_bag(recorded["kalibr"])
    topics = by_topic(messages)
    assert {t: v[0][0] for t, v in topics.items()} == KALIBR_TOPICS
    images = topics["/cam0/image_raw"]
    assert len(images) == N
    for (_, t, img), f in zip(images, frames, strict=True):  # mono8, step = width, as kalibr_bagcreater writes
        assert t == _ns(img.header.stamp) == f.timestamp_ns
        assert (img.encoding, img.height, img.width, img.step, len(img.data)) == ("mono8", 120, 160, 160, 19200)
    assert [t for _, t, _ in topics["/imu0"]] == np.concatenate([f.imu.t_ns for f in frames]).tolist()
    from rosbags.rosbag1 import Reader

    with Reader(recorded["kalibr"]) as bag:  # the md5 sums ROS 1's rosbag (and so Kalibr) checks on reading
        assert {c.topic: c.digest for c in bag.connections} == {
            "/cam0/image_raw": "060021388200f6f0f447d0fcd9c64743", "/imu0": "6a62c6daae103f4ff57a132d6f95cec2"}
    import yaml

    chain = yaml.safe_load((recorded["kalibr"].parent / "camchain.yaml").read_text())["cam0"]
    assert chain["rostopic"] == "/cam0/image_raw"
    assert chain["line_delay"] == pytest.approx(frames[0].line_time_ns * 1e-9)
    assert yaml.safe_load((recorded["kalibr"].parent / "imu.yaml").read_text())["rostopic"] == "/imu0"


def test_stamps_split_integer_ns_exactly():
    from rollcam.host.robotics.messages import stamp

    t = 30 * 86_400 * 10**9 + 123_456_789  # 30 days of device time
    assert stamp(t) == {"sec": 2_592_000, "nanosec": 123_456_789}
    assert stamp(0) == {"sec": 0, "nanosec": 0}


def test_a_gs_rs_pair_puts_the_global_frame_under_cam0_gs(tmp_path):
    with open_camera("emu:imx219?size=96x64&imu=on&seed=2") as cam:
        capture(cam, tmp_path, 2, shutter="both", fmt="mcap", progress=False)
    topics = by_topic(read_mcap(tmp_path / "capture.mcap"))
    assert len(topics["/cam0_gs/image_raw"]) == len(topics["/cam0/image_raw"]) == 2
    assert {m.shutter for _, _, m in topics["/cam0_gs/rolling_shutter"]} == {"global"}
    assert {m.shutter for _, _, m in topics["/cam0/truth"]} == {"rolling"}


def test_ctrl_c_leaves_a_whole_readable_recording(tmp_path):
    with open_camera(URI) as cam:
        reads = 0
        real = cam.read

        def read():
            nonlocal reads
            reads += 1
            if reads == 3:
                ctrl_c()
            return real()

        cam.read = read
        with pytest.raises(CaptureInterrupted) as exc:
            capture(cam, tmp_path, 10, fmt="mcap", progress=False)
    assert exc.value.result.frames == 2 and exc.value.result.recording == tmp_path / "capture.mcap"
    assert len(by_topic(read_mcap(tmp_path / "capture.mcap"))["/cam0/image_raw"]) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["camchain.yaml", "capture.json", "capture.mcap",
                                                          "imu.yaml"]  # no stage left


@pytest.mark.parametrize("fmt", ["mcap", "ros2bag", "rosbag1"])
def test_an_instant_cut_short_leaves_no_recording(tmp_path, frames, fmt):
    w = BagWriter(tmp_path, fmt)
    w.write([frames[0]])
    w._backend.write = lambda *a: ctrl_c()  # the interrupt lands between two messages of the instant
    with pytest.raises(KeyboardInterrupt):
        w.write([frames[1]])
    w.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["camchain.yaml", "imu.yaml"]  # no recording, no stage


def test_bad_input_is_refused_before_anything_is_written(tmp_path):
    with open_camera("emu:imx219?size=96x64&format=YUYV") as cam, pytest.raises(ConfigError, match="YUYV"):
        capture(cam, tmp_path / "yuyv", 1, fmt="mcap", progress=False)
    with open_camera("emu:imx219?size=96x64") as cam, pytest.raises(ConfigError, match="not one of"):
        capture(cam, tmp_path / "x", 1, fmt="rosbag3", progress=False)
    with open_camera("emu:imx219?size=96x64") as cam, pytest.raises(ConfigError, match="kalibr"):
        capture(cam, tmp_path / "k", 1, fmt="kalibr", shutter="both", progress=False)
    assert not (tmp_path / "yuyv").exists() and not (tmp_path / "k").exists()


def test_a_missing_library_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "mcap_ros2.writer", None)
    with pytest.raises(MissingDependencyError, match=r"rollcam\[robotics\]"):
        require_libraries("mcap")


def test_cli_records_and_refuses(tmp_path, capsys):
    from rollcam.host.cli import main

    out = tmp_path / "rec"
    assert main(["capture", "emu:imx219?size=96x64&imu=on", "--frames", "2", "--out", str(out), "--format",
                 "rosbag1"]) == 0
    assert "capture.bag" in capsys.readouterr().out
    assert len(by_topic(read_bag(out / "capture.bag"))["/cam0/image_raw"]) == 2
    assert main(["capture", "emu:imx219?size=96x64", "--frames", "1", "--out", str(out), "--format", "mcap"]) == 2
    assert "already holds a capture" in capsys.readouterr().err
    assert main(["capture", "emu:imx219?size=96x64", "--frames", "1", "--out", str(out), "--format", "mcap",
                 "--overwrite"]) == 0
    assert not (out / "capture.bag").exists() and (out / "capture.mcap").exists()
    capsys.readouterr()
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["capture", "emu:imx219?size=96x64", "--frames", "1", "--out", str(blocker / "sub"), "--format",
                 "mcap"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("rollcam: error:") and len(err.strip().splitlines()) == 1
    assert main(["capture", "emu:imx219", "--frames", "1", "--out", str(out), "--format", "rosbag3"]) == 2
    assert "invalid choice: 'rosbag3'" in capsys.readouterr().err


def test_mjpg_frames_go_as_compressed_images_and_raw_bayer_as_bayer16(tmp_path):
    import cv2

    with open_camera("emu:imx219?size=96x64&format=MJPG&seed=1") as cam:
        capture(cam, tmp_path / "jpeg", 2, fmt="mcap", progress=False)
        ref = cam.read()
    topics = by_topic(read_mcap(tmp_path / "jpeg" / "capture.mcap"))
    assert "/cam0/image_raw" not in topics and len(topics["/cam0/image_raw/compressed"]) == 2
    typ, _, msg = topics["/cam0/image_raw/compressed"][0]
    assert typ == "sensor_msgs/msg/CompressedImage" and msg.format == "jpeg"
    assert cv2.imdecode(np.frombuffer(bytes(msg.data), np.uint8), cv2.IMREAD_COLOR).shape == (64, 96, 3)
    assert ref.format == "MJPG"
    with open_camera("emu:imx219?size=96x64&format=RG10&seed=1") as cam:
        capture(cam, tmp_path / "raw", 1, fmt="ros2bag", progress=False)
    with open_camera("emu:imx219?size=96x64&format=RG10&seed=1") as cam:
        raw = cam.read()
    _, _, img = by_topic(read_bag(tmp_path / "raw" / "capture_ros2"))["/cam0/image_raw"][0]
    assert (img.encoding, img.step, img.is_bigendian) == ("bayer_rggb16", 192, 0)
    assert np.array_equal(np.frombuffer(bytes(img.data), "<u2").reshape(64, 96), raw.data)


def test_overwrite_clears_a_killed_recordings_stage(tmp_path):
    with open_camera("emu:imx219?size=96x64") as cam:
        capture(cam, tmp_path, 1, fmt="ros2bag", progress=False)
    stage = tmp_path / ".capture_ros2.999-abcd1234.part"  # what a kill -9 in the middle leaves
    (stage / "capture_ros2").mkdir(parents=True)
    with open_camera("emu:imx219?size=96x64") as cam:
        capture(cam, tmp_path, 1, fmt="ros2bag", overwrite=True, progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["capture.json", "capture_ros2"]


def test_kill_9_leaves_no_recording_and_overwrite_clears_its_stage(tmp_path):
    import signal
    import time

    out = tmp_path / "cap"
    code = ("import sys; from rollcam.host.cli import main; sys.exit(main(['capture', sys.argv[1], '--frames', "
            "'100000', '--out', sys.argv[2], '--format', 'ros2bag']))")
    proc = subprocess.Popen([sys.executable, "-c", code, "emu:imx219?size=96x64&imu=on", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120  # until the bag holds a few instants (its storage file grows)
        while time.monotonic() < deadline and proc.poll() is None:
            staged = list(out.glob(".capture_ros2.*.part/capture_ros2/*.db3")) if out.exists() else []
            if staged and (out / "camchain.yaml").exists() and staged[0].stat().st_size > 20_000:
                break
            time.sleep(0.02)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read()
    assert not (out / "capture_ros2").exists() and len(list(out.glob(".capture_ros2.*.part"))) == 1
    with open_camera("emu:imx219?size=96x64") as cam:
        capture(cam, out, 1, fmt="mcap", overwrite=True, progress=False)
    assert sorted(p.name for p in out.iterdir()) == ["capture.json", "capture.mcap"]
