"""The emulated IMU: consistent with the rendered motion, Kalibr noise terms, exact clocks, every door."""

from __future__ import annotations

import dataclasses
import json
import urllib.request

import numpy as np
import pytest
from rollcam.benchmarks.imu import allan_deviation, fit_allan
from rollcam.common.errors import ConfigError, SourceError
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.protocol import handle_line
from rollcam.firmware.spec import CameraSpec
from rollcam.host import open_camera
from rollcam.sim.imu import Imu, ImuParams
from rollcam.sim.pose import Trajectory, rotation_vector_to_matrix
from rollcam.sim.render.renderer import Renderer
from rollcam.sim.scene import Camera
from rollcam.sim.scenegen import ego_preset, make_street_scene

DAY_NS = 86_400 * 10**9
PRESETS = ("none", "pan", "walk", "vehicle", "drone", "calib")


def _camera(ego: str) -> Camera:
    return make_street_scene(0, width=160, height=120, ego=ego_preset(ego), n_pedestrians=0).camera(0)


@pytest.mark.parametrize("ego", PRESETS)
def test_trajectory_is_the_renderers_pose(ego: str) -> None:
    cam = _camera(ego)
    t = np.linspace(0.0, 3.0, 37) + 17.25
    rot, pos = Renderer(make_street_scene(0, width=160, height=120, ego=ego_preset(ego), n_pedestrians=0),
                        cam).poses(t)
    k = Trajectory(cam).at(t)
    np.testing.assert_allclose(k.rotation.transpose(0, 2, 1), rot, atol=1e-12)
    np.testing.assert_allclose(k.position, pos, atol=1e-9)


@pytest.mark.parametrize("ego", ("pan", "drone"))
def test_derivatives_match_differences_of_the_pose(ego: str) -> None:
    traj, t, h = Trajectory(_camera(ego)), np.linspace(1.0, 2.0, 9), 1e-6
    k, kp, km = traj.at(t), traj.at(t + h), traj.at(t - h)
    np.testing.assert_allclose((kp.position - km.position) / (2 * h), k.velocity, atol=1e-5)
    np.testing.assert_allclose((kp.velocity - km.velocity) / (2 * h), k.acceleration, atol=1e-3)
    d = np.einsum("nji,njk->nik", km.rotation, kp.rotation)
    w = np.stack([d[:, 2, 1] - d[:, 1, 2], d[:, 0, 2] - d[:, 2, 0], d[:, 1, 0] - d[:, 0, 1]], 1) / (4 * h)
    np.testing.assert_allclose(w, k.angular_velocity, atol=1e-5)


def _ideal(**kw) -> ImuParams:
    return ImuParams(gyroscope_noise_density=0.0, gyroscope_random_walk=0.0, accelerometer_noise_density=0.0,
                     accelerometer_random_walk=0.0, **kw)


@pytest.mark.parametrize("ego", ("pan", "walk", "drone"))
def test_gyro_integral_is_the_true_rotation(ego: str) -> None:
    """Integrating the (noise-free) gyro over 2 s gives the rotation between the renderer's poses, through a
    non-trivial camera-IMU rotation and time offset."""
    cam = _camera(ego)
    p = _ideal(rate_hz=2000, rotation_cam_imu_deg=(10.0, -80.0, 30.0), time_offset_ns=1_234_567)
    s = Imu(p, Trajectory(cam)).samples(10**9, 3 * 10**9)
    from rollcam.sim.rscorrect import gyro_line_rotations

    t0, t1 = int(s.t_ns[0] - p.time_offset_ns), int(s.t_ns[-1] - p.time_offset_ns)
    rel = gyro_line_rotations(s, np.array([t1]), t0)[0]  # camera at t1 <- camera at t0
    rot, _ = Renderer(make_street_scene(0, width=160, height=120, ego=ego_preset(ego), n_pedestrians=0),
                      cam).poses(np.array([t0, t1]) * 1e-9)
    true = rot[1] @ rot[0].T
    angle = np.degrees(np.arccos(np.clip((np.trace(rel.T @ true) - 1) / 2, -1, 1)))
    total = np.degrees(np.arccos(np.clip((np.trace(true) - 1) / 2, -1, 1)))
    assert total > 0.05 and angle < 2e-3 * max(total, 1.0)


def test_accelerometer_reads_gravity_and_the_lever_arm() -> None:
    still = Imu(_ideal(rotation_cam_imu_deg=(0.0, 0.0, 90.0)), Trajectory(Camera("c", 64, 48, 4.0, 4.0, (0, 0, 1))))
    s = still.samples(0, 10**8)
    # a level camera: y down, so the specific force (up) is -y in camera axes; the IMU is turned 90 deg about z
    up_cam = np.array([0.0, -9.80665, 0.0])
    np.testing.assert_allclose(s.accel, np.tile(rotation_vector_to_matrix(np.radians([0, 0, 90.0])).T @ up_cam,
                                                (len(s), 1)), atol=1e-9)
    np.testing.assert_allclose(s.gyro, 0.0, atol=1e-12)
    spin = dataclasses.replace(_camera("pan"), ego=dataclasses.replace(ego_preset("none"), pan_dps=90.0))
    arm = Imu(_ideal(translation_cam_imu_m=(0.1, 0.0, 0.0)), Trajectory(spin)).samples(0, 10**8)
    centripetal = np.linalg.norm(arm.accel - Imu(_ideal(), Trajectory(spin)).samples(0, 10**8).accel, axis=1)
    np.testing.assert_allclose(centripetal, 0.1 * np.radians(90.0) ** 2 * np.cos(np.radians(spin.pitch_deg)) ** 2,
                               rtol=0.02)


def test_allan_deviation_recovers_the_configured_terms() -> None:
    p = ImuParams(rate_hz=200, gyroscope_noise_density=1e-3, gyroscope_random_walk=1e-3,
                  accelerometer_noise_density=2e-2, accelerometer_random_walk=5e-3)
    s = Imu(p, Trajectory(Camera("c", 64, 48, 4.0, 4.0, (0, 0, 1))), seed=7).samples(0, 600 * 10**9)
    taus = np.logspace(np.log10(0.01), np.log10(60.0), 30)
    for data, n_cfg, k_cfg in ((s.gyro, 1e-3, 1e-3), (s.accel - s.accel.mean(0), 2e-2, 5e-3)):
        tau, adev = allan_deviation(data, 200, taus)
        fits = np.array([fit_allan(tau, adev[:, i]) for i in range(3)])
        assert abs(fits[:, 0].mean() / n_cfg - 1) < 0.05
        assert abs(fits[:, 1].mean() / k_cfg - 1) < 0.25
        # the short-tau end is the white noise alone: sigma(tau) = N / sqrt(tau)
        np.testing.assert_allclose(adev[0], n_cfg / np.sqrt(tau[0]), rtol=0.05)


def test_noise_depends_only_on_seed_and_index() -> None:
    imu = Imu(ImuParams(), Trajectory(Camera("c", 64, 48, 4.0, 4.0, (0, 0, 1))), seed=3)
    whole = imu.samples(0, 2 * 10**9)
    part = imu.samples(10**9, 2 * 10**9)
    np.testing.assert_array_equal(part.gyro, whole.gyro[400:])
    np.testing.assert_array_equal(part.accel, whole.accel[400:])
    other = Imu(ImuParams(), imu.trajectory, seed=4).samples(0, 10**9)
    assert not np.array_equal(other.gyro, whole.gyro[:400])
    # the bias walk's increments are N(0, 1) in walk units whatever the index
    walk = imu.noise(range(5 * 10**9, 5 * 10**9 + 20000))[2]
    assert abs(np.diff(walk, axis=0).std() - 1) < 0.03


@pytest.mark.parametrize("rate", (100, 400, 2000, 333))
def test_stamps_exact_after_30_days_and_no_drift(rate: int) -> None:
    p = ImuParams(rate_hz=rate)
    imu = Imu(p, Trajectory(_camera("pan")))
    t0 = 30 * DAY_NS + 12345
    s = imu.samples(t0, t0 + 10**9)
    k = s.index
    assert s.t_ns.dtype == np.int64 and s.t_ns[0] >= t0
    assert [int(v) for v in s.t_ns] == [int(i) * 10**9 // rate for i in k]  # closed form, exact
    assert len(s) in (rate, rate + 1) and k[0] == -((-t0 * rate) // 10**9)
    # the frame clock and the IMU clock are one clock: after 30 days, 30 days of samples
    assert p.first_index(30 * DAY_NS) == 30 * 86_400 * rate


def test_frames_partition_the_imu_stream_at_2khz() -> None:
    src = open_camera("emu:imx219?size=640x480&ego=drone&imu_rate=2000&frames=6&start_ns=" + str(30 * DAY_NS))
    frames = list(src)
    t = np.concatenate([f.imu.t_ns for f in frames])
    assert np.all(np.diff(t) == 500_000)  # none lost, none repeated, no drift against the frames
    for f in frames:
        assert f.imu.t_ns[-1] <= f.timestamp_ns + f.exposure_ns + int(f.row_times_ns[-1] - f.row_times_ns[0])
        assert f.poses.t_ns.tolist() == f.row_times_ns.tolist()
    gs, rs = open_camera("emu:imx219?size=640x480&ego=pan&imu=on").read_pair()
    np.testing.assert_array_equal(gs.imu.t_ns, rs.imu.t_ns)


def test_frames_remade_after_a_control_change_still_partition_the_stream() -> None:
    """The pump makes frames ahead and remakes them after a control change: the IMU windows follow."""
    from rollcam.firmware.imaging import Imager
    from rollcam.firmware.imu import FrameImu, frame_end_ns

    spec = CameraSpec.from_options("imx219", {"size": "320x240", "ego": "pan", "imu_rate": "1000"})
    longer = spec.with_options({"exposure_us": "20000"})
    scene_camera = Imager().camera(spec).camera
    tap = FrameImu()
    period = spec.settings.timing.frame_period_ns
    made = {n: tap.samples(spec, scene_camera, n, n * period) for n in range(4)}  # 0..3 made ahead
    made[2] = tap.samples(longer, scene_camera, 2, 2 * period)  # exposure changed: 2 and 3 remade
    made[3] = tap.samples(longer, scene_camera, 3, 3 * period)
    k = np.concatenate([made[n].index for n in range(4)])
    assert np.all(np.diff(k) == 1), "samples lost or repeated across a remade frame"
    assert made[3].t_ns[-1] <= frame_end_ns(longer, 3 * period)
    assert tap.samples(longer, scene_camera, 3, 3 * period).index.tolist() == made[3].index.tolist()  # re-asked


def test_imu_options_at_every_door() -> None:
    spec = CameraSpec.from_options("imx219", {"imu_rate": "1000", "imu_offset_us": "-250",
                                              "imu_rotation_deg": "0,0,90"})
    assert spec.imu.rate_hz == 1000 and spec.imu.time_offset_ns == -250_000
    assert spec.option_values()["imu_rotation_deg"] == (0.0, 0.0, 90.0)
    assert spec.with_options({"imu": "off"}).imu is None
    assert CameraSpec.from_options("imx219", {}).imu is None
    with pytest.raises(ConfigError, match="imu_rate"):
        CameraSpec.from_options("imx219", {"imu_rate": "5000"})
    with pytest.raises(ConfigError, match="rs_correct=gyro needs"):
        CameraSpec.from_options("imx219", {"rs_correct": "gyro"})
    with pytest.raises(ConfigError, match="rate_hz"):
        ImuParams(rate_hz=50)
    # the hw_config's section is the default the options start from
    oak = CameraSpec.from_options("imx378", {"imu": "on"})
    assert oak.imu == oak.sensor.imu and oak.imu.rate_hz != ImuParams().rate_hz


def test_serial_imu_query() -> None:
    clock = [0]
    cam = FirmwareCamera(CameraSpec.create("imx219", scene={"scene": "street", "ego": "pan"}, size=(640, 480)),
                         clock=lambda: clock[0])
    assert handle_line(cam, "IMU? 0").startswith("ERR 103 the IMU is off")
    assert handle_line(cam, "OPT imu_rate 1000") == "OK 1000"
    clock[0] = 10**9
    reply = handle_line(cam, "IMU? 990000000")
    head, _, rows = reply.partition(" next=")
    assert head == "n=10"
    stamps = [int(r.split(",")[0]) for r in rows.split(" ", 1)[1].split(";")]
    assert stamps == list(range(990_000_000, 10**9, 1_000_000))
    clock[0] = 5 * 10**9  # past the device's 2 s buffer
    assert handle_line(cam, "IMU? 0").startswith("ERR 102 IMU samples from 0 ns are gone")


def test_http_imu_jsonl() -> None:
    from rollcam.emu.http.mjpeg import MjpegServer

    cam = FirmwareCamera(CameraSpec.create("imx219", scene={"scene": "street", "ego": "pan", "pedestrians": 0},
                                           size=(640, 480), imu_values={"imu_rate": 2000}))
    with MjpegServer(cam) as srv:
        host, port = srv.address
        with urllib.request.urlopen(f"http://{host}:{port}/imu.jsonl?samples=600", timeout=20) as r:
            lines = r.read().decode().splitlines()
        with pytest.raises(urllib.error.HTTPError, match="400"):
            urllib.request.urlopen(f"http://{host}:{port}/imu.jsonl?samples=x", timeout=5)
    head = json.loads(lines[0])["imu"]
    assert head["rate_hz"] == 2000 and len(lines) == 601
    t = np.array([json.loads(x)["t_ns"] for x in lines[1:]])
    assert np.all(np.diff(t) == 500_000)  # real time at 2 kHz, no sample dropped


def test_capture_writes_euroc_and_kalibr_files(tmp_path) -> None:
    import yaml
    from rollcam.host.recording.capture import capture

    out = tmp_path / "cap"
    with open_camera("emu:imx219?size=640x480&ego=pan&imu_rate=400&imu_offset_us=120&frames=3") as src:
        capture(src, out, 3, shutter="both")
    imu = np.loadtxt(out / "imu.csv", delimiter=",", comments="#")
    assert imu.shape[1] == 7 and np.all(np.diff(imu[:, 0]) == 2_500_000)
    assert (out / "imu.csv").read_text().startswith("#timestamp [ns],w_RS_S_x [rad s^-1]")
    poses = np.loadtxt(out / "camera_poses.csv", delimiter=",", comments="#")
    assert poses.shape == (3 * 480, 16)
    chain = yaml.safe_load((out / "camchain.yaml").read_text())["cam0"]
    assert chain["timeshift_cam_imu"] == pytest.approx(120e-6) and chain["resolution"] == [640, 480]
    assert np.allclose(chain["T_cam_imu"], np.eye(4)) and chain["line_delay"] == pytest.approx(18904e-9)
    kal = yaml.safe_load((out / "imu.yaml").read_text())
    assert kal["update_rate"] == 400.0 and kal["gyroscope_noise_density"] == pytest.approx(1.6968e-4)
    assert yaml.safe_load((out / "camera.yaml").read_text())["intrinsics"][2] == pytest.approx(319.5)


def test_gyro_correction_brings_rs_to_gs() -> None:
    """Device-side and host-side correction agree, and bring an RS frame of a panning camera to within a
    fraction of the RS error of the GS frame of the same instant."""
    from rollcam.host.correction.gyro import GyroCorrector

    base = "emu:imx219?size=640x480&ego=pan&pedestrians=0&imu=on"
    gs, rs = open_camera(base).read_pair()
    device = open_camera(base + "&rs_correct=gyro").read()
    host = GyroCorrector().correct(rs)
    g = gs.data.astype(np.int16)
    inner = (slice(20, -20), slice(40, -40))
    err_rs = np.abs(g - rs.data)[inner].mean()
    err_dev = np.abs(g - device.data)[inner].mean()
    err_host = np.abs(g - host.data)[inner].mean()
    assert err_dev < 0.3 * err_rs and err_host < 0.3 * err_rs
    assert np.abs(device.data.astype(np.int16) - host.data)[inner].mean() < 0.5
    assert device.meta["rs_correct"] == "gyro" and host.meta["rs_correct"] == "gyro-host"
    with pytest.raises(SourceError, match="IMU samples"):
        GyroCorrector().correct(open_camera("emu:imx219?size=640x480").read())


def test_coarse_resampling_map_matches_the_exact_one() -> None:
    from rollcam.sim.rscorrect import gyro_line_rotations, unwarp

    src = open_camera("emu:imx219?size=640x480&ego=drone&imu=on&pedestrians=0")
    rs = src.read()
    t = rs.row_times_ns
    s = src.device.imager.imu.imu(src.spec, src.camera.camera).samples(int(t[0]) - 10**7, int(t[-1]) + 10**7)
    rot = gyro_line_rotations(s, t, int(t[0]))
    exact, v1 = unwarp(rs.data, rot, tuple(rs.meta["intrinsics"]), grid_px=1)
    coarse, v8 = unwarp(rs.data, rot, tuple(rs.meta["intrinsics"]))
    assert np.abs(exact.astype(np.int16) - coarse)[v1 & v8].mean() < 0.05
