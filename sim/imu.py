"""An emulated 6-axis IMU beside the camera: gyro and accelerometer on the camera's integer-ns device clock.

The IMU reads the motion the images show (``rollcam.sim.pose.Trajectory``, the renderer's own camera motion):
the gyro the angular velocity of the IMU frame, the accelerometer the specific force (acceleration minus
gravity) of the IMU's origin, both in IMU axes. It sits at a fixed pose in the camera frame (``T_cam_imu``
maps IMU coordinates to camera coordinates, as Kalibr writes it) and its stamps are offset from the camera's
by ``time_offset_ns`` (Kalibr's ``timeshift_cam_imu``: t_imu = t_cam + shift, so a sample stamped ``s``
measures the instant ``s - shift`` of the camera's clock).

Sample ``k`` is stamped ``floor(k * 1e9 / rate_hz)`` ns of device time, closed form, so stamps are exact after
any uptime and never drift against the row times. Noise is Kalibr's IMU model: per axis

    measured = M @ true + b(t) + n(t),   n: white, density sigma_N;  b: random walk, density sigma_b

in discrete time ``n_k = sigma_N * sqrt(rate) * N(0, 1)`` and ``b_k = sigma_b / sqrt(rate) * W(k)`` (``W`` a
unit-step random walk from device boot), with M an optional scale-and-misalignment matrix. Every draw is
counter-based (``rollcam.sim._imunoise``): a sample depends only on (seed, k).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from rollcam.common.errors import ConfigError

from .configschema import Checked, ListOf, Rule, nonnegative, positive, spec
from .pose import Kinematics, Trajectory, rotation_vector_to_matrix

NS_PER_S = 1_000_000_000
MIN_RATE_HZ, MAX_RATE_HZ = 100, 2000
MAX_OFFSET_NS = NS_PER_S
MAX_SAMPLES = 1 << 24
"""Most samples one call returns (2.3 h at 2 kHz; 6 float64 a sample, ~800 MB with the truth)."""
_IDENTITY = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)


def _vec(n: int, what: str) -> Any:
    return lambda v: len(v) == n and all(math.isfinite(x) for x in v)


@dataclass(frozen=True, kw_only=True)
class ImuParams(Checked):
    """An IMU's figures in Kalibr's terms and its place beside the camera (hw_config section ``imu``).

    Defaults: the EuRoC MAV's ADIS16448 as Kalibr's IMU model page lists it, 400 Hz, mounted at the camera's
    optical centre with the camera's axes.
    """

    rate_hz: int = spec(int, f"an integer in {MIN_RATE_HZ}..{MAX_RATE_HZ} (Hz)",
                        lambda v: MIN_RATE_HZ <= v <= MAX_RATE_HZ, 400)
    gyroscope_noise_density: float = spec(float, "a number >= 0 (rad/s/sqrt(Hz))", nonnegative, 1.6968e-04)
    gyroscope_random_walk: float = spec(float, "a number >= 0 (rad/s^2/sqrt(Hz))", nonnegative, 1.9393e-05)
    accelerometer_noise_density: float = spec(float, "a number >= 0 (m/s^2/sqrt(Hz))", nonnegative, 2.0e-03)
    accelerometer_random_walk: float = spec(float, "a number >= 0 (m/s^3/sqrt(Hz))", nonnegative, 3.0e-03)
    gyroscope_scale_misalignment: tuple[float, ...] = spec(
        ListOf(float), "9 numbers, a 3x3 matrix by rows (identity: none)", _vec(9, "M"), _IDENTITY)
    accelerometer_scale_misalignment: tuple[float, ...] = spec(
        ListOf(float), "9 numbers, a 3x3 matrix by rows (identity: none)", _vec(9, "M"), _IDENTITY)
    rotation_cam_imu_deg: tuple[float, ...] = spec(
        ListOf(float), "3 numbers, the rotation vector of R_cam_imu (deg)", _vec(3, "r"), (0.0, 0.0, 0.0))
    translation_cam_imu_m: tuple[float, ...] = spec(
        ListOf(float), "3 numbers, the IMU's origin in camera coordinates (m)", _vec(3, "t"), (0.0, 0.0, 0.0))
    time_offset_ns: int = spec(int, f"an integer in -{MAX_OFFSET_NS}..{MAX_OFFSET_NS} (ns, t_imu = t_cam + offset)",
                               lambda v: abs(v) <= MAX_OFFSET_NS, 0)
    gravity_mps2: float = spec(float, "a positive number (m/s^2)", positive, 9.80665)
    _rules: ClassVar[tuple[Rule, ...]] = (
        Rule("rotation_cam_imu_deg", lambda s, _, i: math.hypot(*s.rotation_cam_imu_deg) <= 360.0,
              lambda s, _, i: "a rotation of at most 360 deg"),
    )

    @property
    def R_cam_imu(self) -> np.ndarray:
        """Rotation taking IMU coordinates to camera coordinates (3, 3)."""
        return rotation_vector_to_matrix(np.radians(np.asarray(self.rotation_cam_imu_deg, np.float64)))

    @property
    def T_cam_imu(self) -> np.ndarray:
        """The 4x4 transform from IMU to camera coordinates, as Kalibr's camchain writes it."""
        t = np.eye(4)
        t[:3, :3] = self.R_cam_imu
        t[:3, 3] = self.translation_cam_imu_m
        return t

    def stamp_ns(self, k: int) -> int:
        """Device time of sample ``k`` (exact for any k)."""
        return int(k) * NS_PER_S // self.rate_hz

    def first_index(self, t_ns: int) -> int:
        """The first sample stamped at or after ``t_ns`` (0 before boot)."""
        return max(-((-int(t_ns) * self.rate_hz) // NS_PER_S), 0)


@dataclass(frozen=True, eq=False)
class ImuSamples:
    """Consecutive IMU samples: ``index`` (k), ``t_ns`` (int64 device-clock stamps), ``gyro`` (rad/s) and
    ``accel`` (m/s^2) in IMU axes (n, 3) float64; ``params`` the IMU that made them (its calibration)."""

    index: np.ndarray
    t_ns: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    params: ImuParams = field(repr=False)

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

    def __repr__(self) -> str:
        span = f"{self.t_ns[0]}..{self.t_ns[-1]} ns" if len(self) else "empty"
        return f"ImuSamples({len(self)} at {self.params.rate_hz} Hz, {span})"

    def to_rows(self) -> list[list[float | int]]:
        """One ``[t_ns, wx, wy, wz, ax, ay, az]`` list per sample (JSON, CSV and the serial line)."""
        return [[int(t), *map(float, g), *map(float, a)] for t, g, a in zip(self.t_ns, self.gyro, self.accel,
                                                                           strict=True)]

    @classmethod
    def concat(cls, parts: list[ImuSamples]) -> ImuSamples:
        """The samples of several blocks of one IMU, in order."""
        if not parts:
            raise ConfigError("no IMU blocks to join")
        return cls(*(np.concatenate([getattr(p, n) for p in parts]) for n in ("index", "t_ns", "gyro", "accel")),
                   params=parts[0].params)


class Imu:
    """The IMU of one camera: ``samples(t0, t1)`` are those stamped in ``[t0, t1)`` of device time."""

    def __init__(self, params: ImuParams, trajectory: Trajectory, seed: int = 0) -> None:
        self.params = params
        self.trajectory = trajectory
        digest = hashlib.blake2b(repr(("imu", int(seed))).encode(), digest_size=8).digest()
        self._key = np.uint64(int.from_bytes(digest, "little"))
        self._m_gyro = np.asarray(params.gyroscope_scale_misalignment, np.float64).reshape(3, 3)
        self._m_accel = np.asarray(params.accelerometer_scale_misalignment, np.float64).reshape(3, 3)
        self._r_ci = params.R_cam_imu

    def __repr__(self) -> str:
        return f"Imu({self.params.rate_hz} Hz, offset {self.params.time_offset_ns} ns)"

    def indices(self, t0_ns: int, t1_ns: int) -> range:
        """Sample indices stamped in ``[t0_ns, t1_ns)``."""
        p = self.params
        return range(p.first_index(t0_ns), max(p.first_index(t1_ns), p.first_index(t0_ns)))

    def samples(self, t0_ns: int, t1_ns: int) -> ImuSamples:
        """Measured samples stamped in ``[t0_ns, t1_ns)`` (noise and biases included)."""
        idx = self.indices(t0_ns, t1_ns)
        gyro, accel = self.true_rates(idx)
        noise = self.noise(idx)
        p = self.params
        rate = float(p.rate_hz)
        gyro = gyro @ self._m_gyro.T + noise[0] * (p.gyroscope_noise_density * math.sqrt(rate)) \
            + noise[2] * (p.gyroscope_random_walk / math.sqrt(rate))
        accel = accel @ self._m_accel.T + noise[1] * (p.accelerometer_noise_density * math.sqrt(rate)) \
            + noise[3] * (p.accelerometer_random_walk / math.sqrt(rate))
        return ImuSamples(np.arange(idx.start, idx.stop, dtype=np.int64), self._stamps(idx), gyro, accel, p)

    def _stamps(self, idx: range) -> np.ndarray:
        k = np.arange(idx.start, idx.stop, dtype=np.int64)
        # floor(k * 1e9 / rate) without int64 overflow: k * q + floor(k * rem / rate)
        q, rem = divmod(NS_PER_S, self.params.rate_hz)
        return k * q + (k * rem) // self.params.rate_hz

    def kinematics(self, idx: range) -> Kinematics:
        """The camera's true motion at the instants samples ``idx`` measure (stamp minus the time offset)."""
        return self.trajectory.at_ns(self._stamps(idx) - self.params.time_offset_ns)

    def true_rates(self, idx: range) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free gyro (rad/s) and accelerometer (m/s^2) readings of samples ``idx``, IMU axes."""
        if len(idx) > MAX_SAMPLES:
            raise ConfigError(f"{len(idx)} IMU samples asked for at once; at most {MAX_SAMPLES}")
        kin = self.kinematics(idx)
        r_ci, t_ci = self._r_ci, np.asarray(self.params.translation_cam_imu_m, np.float64)
        gyro = kin.angular_velocity @ r_ci  # R_ci^T w_c, row-wise
        lever = np.einsum("nij,j->ni", kin.rotation, t_ci)  # IMU origin from the camera centre, world axes
        om = kin.angular_velocity_world
        acc = kin.acceleration + np.cross(kin.angular_acceleration, lever) + np.cross(om, np.cross(om, lever))
        acc[:, 2] += self.params.gravity_mps2  # specific force: a - g, with g = (0, 0, -gravity)
        f_cam = np.einsum("nji,nj->ni", kin.rotation, acc)  # R_cw a
        return gyro, f_cam @ r_ci

    def noise(self, idx: range) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Unit white noise and unit random walks of samples ``idx``: gyro white, accel white, gyro walk,
        accel walk, each (n, 3); the IMU scales them by its densities."""
        from ._imunoise import white_and_walk

        n = len(idx)
        out = [np.empty((n, 3)) for _ in range(4)]
        white_and_walk(self._key, idx.start, n, 0, 8, out[0], out[2])
        white_and_walk(self._key, idx.start, n, 3, 11, out[1], out[3])
        return out[0], out[1], out[2], out[3]
