"""A capture's IMU stream, per-line ground truth and calibration files, in the layouts calibration tools read.

``imu.csv`` is the EuRoC ``imu0/data.csv`` layout (``#timestamp [ns],w_RS_S_x [rad s^-1],...,a_RS_S_z
[m s^-2]``), which Kalibr's ``kalibr_bagcreater`` also reads (it skips the header line). ``camera_poses.csv``
is the true camera pose at every line's sample time (frame sequence, line, position, quaternion w x y z of
camera-to-world, velocity in world, angular velocity in camera axes). ``imu.yaml`` is Kalibr's IMU
configuration (noise densities and random walks, rate), ``camchain.yaml`` Kalibr's camera chain (pinhole
intrinsics, resolution, ``T_cam_imu``, ``timeshift_cam_imu``, and the rolling shutter's ``line_delay``),
``camera.yaml`` EuRoC's ``cam0/sensor.yaml``. Every row is appended through ``rollcam.common.files.AppendLog``
(whole lines or none) and the YAML files are written atomically.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from rollcam.common.files import OS_FS, AppendLog, FileSystem, write_atomic
from rollcam.sim.frame import Frame
from rollcam.sim.imu import ImuParams

IMU_CSV, POSES_CSV = "imu.csv", "camera_poses.csv"
IMU_YAML, CAMCHAIN_YAML, CAMERA_YAML = "imu.yaml", "camchain.yaml", "camera.yaml"
FILES = (IMU_CSV, POSES_CSV, IMU_YAML, CAMCHAIN_YAML, CAMERA_YAML)
IMU_HEADER = ("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
              "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n")
POSES_HEADER = ("#timestamp [ns],sequence,line,p_x [m],p_y [m],p_z [m],q_w [],q_x [],q_y [],q_z [],"
                "v_x [m s^-1],v_y [m s^-1],v_z [m s^-1],w_x [rad s^-1],w_y [rad s^-1],w_z [rad s^-1]\n")


def imu_rows(frame: Frame) -> str:
    """The ``imu.csv`` lines of a frame's samples."""
    s = frame.imu
    if s is None or not len(s):
        return ""
    return "".join(f"{t},{g[0]:.9g},{g[1]:.9g},{g[2]:.9g},{a[0]:.9g},{a[1]:.9g},{a[2]:.9g}\n"
                   for t, g, a in zip(s.t_ns.tolist(), s.gyro, s.accel, strict=True))


def pose_rows(frame: Frame) -> str:
    """The ``camera_poses.csv`` lines of a frame's per-line ground truth."""
    k = frame.poses
    if k is None:
        return ""
    q = k.quaternion_wxyz
    cols = np.concatenate([k.position, q, k.velocity, k.angular_velocity], axis=1)
    return "".join(f"{t},{frame.sequence},{i}," + ",".join(f"{v:.12g}" for v in row) + "\n"
                   for i, (t, row) in enumerate(zip(k.t_ns.tolist(), cols, strict=True)))


def _matrix(m: np.ndarray, indent: str) -> str:
    return "".join(f"{indent}- [{', '.join(f'{v:.12g}' for v in row)}]\n" for row in np.asarray(m))


def imu_yaml(p: ImuParams, topic: str = "/imu0") -> str:
    """Kalibr's IMU configuration file."""
    return (f"rostopic: {topic}\nupdate_rate: {float(p.rate_hz)}\n"
            f"accelerometer_noise_density: {p.accelerometer_noise_density:.9g}\n"
            f"accelerometer_random_walk: {p.accelerometer_random_walk:.9g}\n"
            f"gyroscope_noise_density: {p.gyroscope_noise_density:.9g}\n"
            f"gyroscope_random_walk: {p.gyroscope_random_walk:.9g}\n")


def camchain_yaml(frame: Frame, p: ImuParams, topic: str = "/cam0/image_raw") -> str:
    """Kalibr's camera chain: cam0's pinhole intrinsics, its pose from the IMU and its time shift."""
    fx, fy, cx, cy = frame.meta["intrinsics"]
    return ("cam0:\n  camera_model: pinhole\n"
            f"  intrinsics: [{fx:.12g}, {fy:.12g}, {cx:.12g}, {cy:.12g}]\n"
            "  distortion_model: radtan\n  distortion_coeffs: [0.0, 0.0, 0.0, 0.0]\n"
            f"  resolution: [{frame.width}, {frame.height}]\n  rostopic: {topic}\n"
            f"  line_delay: {frame.line_time_ns * 1e-9:.12g}\n"
            f"  timeshift_cam_imu: {p.time_offset_ns * 1e-9:.12g}\n"
            "  T_cam_imu:\n" + _matrix(p.T_cam_imu, "  "))


def camera_yaml(frame: Frame, p: ImuParams, fps: float | None) -> str:
    """EuRoC's ``cam0/sensor.yaml``: the camera's pose in the body (IMU) frame, rate, resolution, intrinsics."""
    fx, fy, cx, cy = frame.meta["intrinsics"]
    t_bs = np.linalg.inv(p.T_cam_imu)  # body = IMU; T_BS takes camera coordinates to IMU coordinates
    rate = f"{fps:.9g}" if fps else "0"
    return ("sensor_type: camera\ncomment: rollcam emulated camera\n"
            "T_BS:\n  cols: 4\n  rows: 4\n  data: [" + ", ".join(f"{v:.12g}" for v in t_bs.ravel()) + "]\n"
            f"rate_hz: {rate}\nresolution: [{frame.width}, {frame.height}]\ncamera_model: pinhole\n"
            f"intrinsics: [{fx:.12g}, {fy:.12g}, {cx:.12g}, {cy:.12g}]\n"
            "distortion_model: radial-tangential\ndistortion_coefficients: [0.0, 0.0, 0.0, 0.0]\n"
            f"line_time_ns: {frame.line_time_ns}\n")


class ImuLog:
    """The IMU files of one capture: calibration YAML at the first frame, then CSV rows frame by frame."""

    def __init__(self, out_dir: Path, frame: Frame, info: dict[str, Any], *, fs: FileSystem = OS_FS) -> None:
        assert frame.imu is not None
        p = frame.imu.params
        write_atomic(out_dir / IMU_YAML, imu_yaml(p).encode(), fs)
        if "intrinsics" in frame.meta:
            write_atomic(out_dir / CAMCHAIN_YAML, camchain_yaml(frame, p).encode(), fs)
            write_atomic(out_dir / CAMERA_YAML, camera_yaml(frame, p, info.get("fps")).encode(), fs)
        self._imu = AppendLog(out_dir / IMU_CSV, truncate=True, fs=fs)
        self._poses = AppendLog(out_dir / POSES_CSV, truncate=True, fs=fs)
        self._imu.append(IMU_HEADER.encode())
        self._poses.append(POSES_HEADER.encode())
        self._last_seq: int | None = None

    def write(self, frames: Sequence[Frame]) -> None:
        """Append one instant's rows: the samples once (a GS/RS pair carries the same), the RS poses."""
        with_imu = [f for f in frames if f.imu is not None]
        if not with_imu or with_imu[0].sequence == self._last_seq:
            return
        self._last_seq = with_imu[0].sequence
        self._imu.append(imu_rows(with_imu[0]).encode())
        posed = next((f for f in with_imu if f.shutter == "rolling"), with_imu[0])
        self._poses.append(pose_rows(posed).encode())

    def close(self) -> None:
        """fsync and close both logs (safe twice)."""
        self._imu.close()
        self._poses.close()
