"""Gyroflow's `.gcsv` beside a captured H.264 video (`rollcam capture --format mp4`), field by field.

The reading side follows Gyroflow's documentation (docs.gyroflow.xyz "GCSV format", version 1.3) and its reader
(telemetry-parser's ``gyroflow/gcsv.rs``): header ``key,value`` rows found in the first 500 bytes, ``t x tscale``
seconds, ``g x gscale`` rad/s, ``a x ascale`` g, the orientation string applied as Gyroflow's ``orient`` does
(axis i = logged axis named by letter i, lower case negated), readout direction codes 0-3. The numbers are
checked against the emulator's own frames and IMU samples of the same URI.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rollcam.common.errors import ConfigError
from rollcam.host import open_camera
from rollcam.host.recording.capture import capture
from rollcam.host.robotics.gcsv import STANDARD_GRAVITY

URI = "emu:imx219?size=160x120&ego=pan&imu=on&imu_rate=400&seed=4"
N = 4


def gyroflow_read(path: Path) -> tuple[list[str], dict[str, str], list[str], np.ndarray]:
    """(the first four lines, the header fields, the column names, the rows) as Gyroflow's reader takes them."""
    raw = path.read_bytes()
    text = raw.decode("ascii")
    lines = text.splitlines()
    header: dict[str, str] = {}
    for line in raw[:500].decode("ascii", "replace").splitlines():  # detection reads the first 500 bytes only
        cells = [c.strip() for c in line.split(",")]
        if cells[0] == "t":
            break
        if len(cells) == 2:
            header[cells[0]] = cells[1]
    start = lines.index(next(line for line in lines if line.startswith("t,")))
    rows = np.array([[float(v) for v in line.split(",")] for line in lines[start + 1:]])
    return lines[:4], header, lines[start].split(","), rows


def orient(v: np.ndarray, orientation: str) -> np.ndarray:
    """Gyroflow's IMU-orientation mapping (imu_transforms.rs ``orient``)."""
    cols = []
    for ch in orientation:
        i = "xyz".index(ch.lower())
        cols.append(v[:, i] if ch.isupper() else -v[:, i])
    return np.stack(cols, axis=1)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    out = tmp_path_factory.mktemp("mp4")
    with open_camera(URI) as cam:
        result = capture(cam, out, N, fmt="mp4", progress=False)
    with open_camera(URI) as cam:
        frames = [cam.read() for _ in range(N)]
    assert result.complete and result.recording == out / "capture.mp4"
    return out, frames


def test_header_fields_follow_the_gcsv_definition(recorded):
    out, frames = recorded
    first, header, columns, _ = gyroflow_read(out / "capture.gcsv")
    assert first == ["GYROFLOW IMU LOG", "version,1.3", "id,rollcam", "orientation,yxz"]  # the mandatory order
    f = frames[0]
    assert header["videofilename"] == "capture.mp4" and (out / header["videofilename"]).exists()
    assert (out / "capture.gcsv").stem == (out / "capture.mp4").stem  # the sidecar name Gyroflow looks for
    assert float(header["frame_readout_time"]) == pytest.approx(120 * f.line_time_ns / 1e6, abs=1e-6)  # ms
    assert header["frame_readout_direction"] == "0"
    assert (float(header["tscale"]), float(header["gscale"]), float(header["ascale"])) == (1e-9, 1.0, 1.0)
    assert sorted(header["orientation"].lower()) == ["x", "y", "z"]
    assert int(header["timestamp"]) > 1_600_000_000 and header["vendor"] == "rollcam"
    assert columns == ["t", "gx", "gy", "gz", "ax", "ay", "az"]


def test_rows_are_the_imu_on_the_videos_clock(recorded):
    out, frames = recorded
    _, header, _, rows = gyroflow_read(out / "capture.gcsv")
    f0 = frames[0]
    origin = int(f0.row_times_ns.min()) + 120 * f0.line_time_ns // 2  # video time 0: the first frame's mid-readout
    stamps = np.concatenate([f.imu.t_ns for f in frames])
    kept = stamps >= origin  # the log starts at video time 0 (Gyroflow's reader times it from its first row)
    assert rows[:, 0].astype(np.int64).tolist() == (stamps[kept] - origin).tolist()
    assert 0 <= rows[0, 0] < 1e9 / 400 and not kept.all()
    seconds = rows[:, 0] * float(header["tscale"])
    period = 1 / open_camera(URI).info()["fps"]
    assert seconds[-1] == pytest.approx((frames[-1].imu.t_ns[-1] - origin) * 1e-9) and seconds[-1] > (N - 2) * period
    gyro = np.concatenate([f.imu.gyro for f in frames])[kept]  # rad/s, camera axes (the IMU is mounted with them)
    accel = np.concatenate([f.imu.accel for f in frames])[kept] / STANDARD_GRAVITY
    np.testing.assert_allclose(rows[:, 1:4] * float(header["gscale"]), gyro, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(rows[:, 4:7] * float(header["ascale"]), accel, rtol=1e-8, atol=1e-12)


def test_orientation_gives_gyroflows_reference_axes(recorded):
    """Mapped by its orientation string as Gyroflow maps it, the log reads the camera's true motion in Gyroflow's
    reference axes (docs: for a camera looking forward, x up, y left, z backwards), the directions taken from
    the emulator's camera pose: rates about them, and gravity's reaction (1 g upwards) along them."""
    out, frames = recorded
    _, header, _, rows = gyroflow_read(out / "capture.gcsv")
    g = orient(rows[:, 1:4], header["orientation"])
    a = orient(rows[:, 4:7], header["orientation"])
    k = frames[1].poses
    rot = k.rotation[0]  # camera-to-world: columns are the camera's right, down, forward in world axes
    up, left, back = -rot[:, 1], -rot[:, 0], -rot[:, 2]
    w_world = rot @ k.angular_velocity[0]
    assert np.linalg.norm(w_world) == pytest.approx(np.radians(30.0), rel=0.01)  # ego=pan: 30 deg/s
    want_g = [w_world @ up, w_world @ left, w_world @ back]
    np.testing.assert_allclose(np.median(g, axis=0), want_g, atol=0.01)
    gravity_reaction = np.array([0.0, 0.0, 1.0])  # at rest an accelerometer reads 1 g upwards (world +Z)
    want_a = [gravity_reaction @ up, gravity_reaction @ left, gravity_reaction @ back]
    np.testing.assert_allclose(np.median(a, axis=0), want_a, atol=0.02)
    assert want_a[0] > 0.95  # the camera is nearly level: Gyroflow's x is (nearly) straight up


def test_the_video_holds_every_frame(recorded):
    av = pytest.importorskip("av")
    out, _ = recorded
    with av.open(str(out / "capture.mp4")) as box:
        stream = box.streams.video[0]
        pictures = [fr.to_ndarray(format="bgr24") for fr in box.decode(stream)]
    assert stream.codec_context.name == "h264" and len(pictures) == N and pictures[0].shape == (120, 160, 3)


@pytest.mark.parametrize(("readout", "code", "lines"), [("bt", "1", 120), ("lr", "2", 160), ("rl", "3", 160)])
def test_readout_direction_codes(tmp_path, readout, code, lines):
    with open_camera(f"emu:imx219?size=160x120&imu=on&readout={readout}") as cam:
        capture(cam, tmp_path, 1, fmt="mp4", progress=False)
        f = cam.read()
    _, header, _, _ = gyroflow_read(tmp_path / "capture.gcsv")
    assert header["frame_readout_direction"] == code
    assert float(header["frame_readout_time"]) == pytest.approx(lines * f.line_time_ns / 1e6, abs=1e-6)


def test_global_shutter_and_no_imu(tmp_path):
    with open_camera("emu:letsroll?size=96x64&imu=on&shutter=global") as cam:
        capture(cam, tmp_path / "gs", 1, fmt="mp4", progress=False)
    _, header, _, _ = gyroflow_read(tmp_path / "gs" / "capture.gcsv")
    assert "frame_readout_time" not in header and "frame_readout_direction" not in header
    with open_camera("emu:imx219?size=96x64") as cam:
        capture(cam, tmp_path / "plain", 1, fmt="mp4", progress=False)
    assert sorted(p.name for p in (tmp_path / "plain").iterdir()) == ["capture.json", "capture.mp4"]


def test_what_one_video_cannot_hold_is_refused_before_writing(tmp_path):
    with open_camera("emu:imx219?size=96x64") as cam, pytest.raises(ConfigError, match="both"):
        capture(cam, tmp_path / "pair", 1, shutter="both", fmt="mp4", progress=False)
    with open_camera("emu:imx219?size=96x64&format=RG10") as cam, pytest.raises(ConfigError, match="RG10"):
        capture(cam, tmp_path / "raw", 1, fmt="mp4", progress=False)
    assert list(tmp_path.iterdir()) == []


def test_ctrl_c_keeps_the_video_and_its_log_whole(tmp_path):
    from interrupts import ctrl_c
    from rollcam.host.recording.capture import CaptureInterrupted

    with open_camera(URI) as cam:
        real, reads = cam.read, []

        def read():
            reads.append(1)
            if len(reads) == 3:
                ctrl_c()
            return real()

        cam.read = read
        with pytest.raises(CaptureInterrupted) as exc:
            capture(cam, tmp_path, 10, fmt="mp4", progress=False)
    assert exc.value.result.frames == 2 and exc.value.result.recording == tmp_path / "capture.mp4"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["capture.gcsv", "capture.json", "capture.mp4"]
    _, header, _, rows = gyroflow_read(tmp_path / "capture.gcsv")
    assert header["videofilename"] == "capture.mp4" and len(rows) > 0


def test_gyroflows_own_reader_finds_and_reads_the_log(recorded):
    """telemetry-parser, the library Gyroflow reads motion data with: it finds the .gcsv beside the video, and
    its normalised IMU (orientation applied, deg/s and m/s^2) is the log's rows mapped as Gyroflow maps them."""
    telemetry_parser = pytest.importorskip("telemetry_parser")
    out, _ = recorded
    _, header, _, rows = gyroflow_read(out / "capture.gcsv")
    parser = telemetry_parser.Parser(str(out / "capture.mp4"))  # the sidecar is found from the video's name
    assert (parser.camera, parser.model) == ("rollcam", "rollcam")
    meta = parser.telemetry()[0]["Default"]["Metadata"]
    assert (meta["version"], meta["frame_readout_time"], meta["frame_readout_direction"]) == (
        "1.3", header["frame_readout_time"], "0")
    imu = parser.normalized_imu()
    assert len(imu) == len(rows)
    t_ms = np.array([s["timestamp_ms"] for s in imu])
    np.testing.assert_allclose(t_ms, (rows[:, 0] - rows[0, 0]) * 1e-6, atol=1e-6)  # timed from its first row
    gyro = np.array([s["gyro"] for s in imu])
    accel = np.array([s["accl"] for s in imu])
    np.testing.assert_allclose(gyro, np.degrees(orient(rows[:, 1:4], header["orientation"])), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(accel, orient(rows[:, 4:7], header["orientation"]) * 9.80665, rtol=1e-9, atol=1e-9)
