"""The camera's ego-motion as kinematics: pose, velocity, acceleration and angular rates at any instant.

``Trajectory(camera)`` evaluates, in closed form, the motion the renderer poses a ``Camera`` with (its
position, yaw/pitch/roll and ``EgoMotion``: constant rates plus a three-axis sinusoidal vibration; the kernel
is ``rollcam.sim.render.world.camera_pose``), together with its time derivatives, so an IMU reads exactly the motion
the images show. ``tests/test_imu.py`` keeps the two equal (``Renderer.poses``) for every ego-motion preset.
Closed form rather than finite differences: an accelerometer's second derivative stays exact after 30 days
of device time, where differencing float64 positions would not.

Frames: world X east, Y north, Z up (m); camera x right, y down, z forward. ``rotation`` is camera-to-world
(``R_wc``, columns right, down, forward in world axes: the transpose of ``Renderer.poses``' rotation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .scene import Camera

NS_PER_S = 1_000_000_000

# The vibration's per-axis frequency multipliers and phases, as rollcam.sim.render.world.camera_pose has them.
_POS_K, _POS_PHASE = (1.0, 1.31, 0.77), (0.0, 1.0, 2.0)
_YAW_K, _PITCH_K, _ROLL_K = (1.13, 0.5), (0.91, 1.7), (1.07, 2.9)


@dataclass(frozen=True, eq=False)
class Kinematics:
    """The camera's state at ``n`` instants: pose, velocity, acceleration, angular velocity (float64).

    ``t_ns`` the instants (device clock, int64); ``rotation`` ``R_wc`` (n, 3, 3); ``position`` the camera
    centre in world (n, 3); ``velocity``, ``acceleration`` in world (n, 3); ``angular_velocity`` in the
    camera frame (n, 3, rad/s); ``angular_acceleration`` in world (n, 3, rad/s^2).
    """

    t_ns: np.ndarray
    rotation: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    angular_velocity: np.ndarray
    angular_acceleration: np.ndarray

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

    @property
    def quaternion_wxyz(self) -> np.ndarray:
        """``rotation`` as unit quaternions (w, x, y, z), w >= 0 (n, 4)."""
        return rotation_to_quaternion(self.rotation)

    @property
    def angular_velocity_world(self) -> np.ndarray:
        """Angular velocity in world axes (n, 3)."""
        return np.einsum("nij,nj->ni", self.rotation, self.angular_velocity)


@dataclass(frozen=True)
class Trajectory:
    """The closed-form motion of one scene camera (see the module docstring)."""

    camera: Camera

    @property
    def moving(self) -> bool:
        """True when the pose changes with time."""
        return self.camera.ego.moving

    def at_ns(self, t_ns: np.ndarray | int) -> Kinematics:
        """Kinematics at device times ``t_ns`` (int64 ns; seconds are formed once, here)."""
        t_ns = np.atleast_1d(np.asarray(t_ns, dtype=np.int64))
        return self.at(t_ns.astype(np.float64) * 1e-9, t_ns)

    def at(self, t_s: np.ndarray, t_ns: np.ndarray | None = None) -> Kinematics:
        """Kinematics at times ``t_s`` (float64 seconds, as the renderer's poses take them)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        cam, ego = self.camera, self.camera.ego
        om = 2.0 * math.pi * ego.vibration_hz
        w = om * t
        va, vp = math.radians(ego.vibration_deg), ego.vibration_m
        rad = math.radians

        def angle(a0_deg: float, rate_dps: float, amp: float, kp: tuple[float, float]):
            k, ph = kp
            s, c = np.sin(k * w + ph), np.cos(k * w + ph)
            return (rad(a0_deg) + rad(rate_dps) * t + amp * s, rad(rate_dps) + amp * k * om * c,
                    -amp * (k * om) ** 2 * s)

        yaw, dyaw, ddyaw = angle(cam.yaw_deg, ego.pan_dps, va, _YAW_K)
        pitch, dpitch, ddpitch = angle(cam.pitch_deg, ego.tilt_dps, va, _PITCH_K)
        roll, droll, ddroll = angle(cam.roll_deg, ego.roll_dps, 0.5 * va, _ROLL_K)
        pos, vel, acc = (np.empty((t.shape[0], 3)) for _ in range(3))
        for i in range(3):
            k, ph = _POS_K[i], _POS_PHASE[i]
            s, c = np.sin(k * w + ph), np.cos(k * w + ph)
            pos[:, i] = cam.position_m[i] + ego.velocity_mps[i] * t + vp * s
            vel[:, i] = ego.velocity_mps[i] + vp * k * om * c
            acc[:, i] = -vp * (k * om) ** 2 * s
        rot_cw, r, f = _rotation(yaw, pitch, roll)
        z = np.zeros_like(r)
        z[:, 2] = 1.0
        # Yaw turns about -Z, pitch about the unrolled right axis r, roll about forward f (see docs/imu.md).
        om_w = -dyaw[:, None] * z + dpitch[:, None] * r + droll[:, None] * f
        om_yaw = -dyaw[:, None] * z
        alpha_w = (-ddyaw[:, None] * z + ddpitch[:, None] * r + dpitch[:, None] * np.cross(om_yaw, r)
                   + ddroll[:, None] * f + droll[:, None] * np.cross(om_w, f))
        om_c = np.einsum("nij,nj->ni", rot_cw, om_w)
        stamps = np.rint(t * 1e9).astype(np.int64) if t_ns is None else np.asarray(t_ns, np.int64)
        return Kinematics(stamps, rot_cw.transpose(0, 2, 1).copy(), pos, vel, acc, om_c, alpha_w)


def _rotation(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray):
    """World-to-camera rotations (rows right, down, forward), the unrolled right axes and the forward axes."""
    sy, cy, sp, cp, sr, cr = np.sin(yaw), np.cos(yaw), np.sin(pitch), np.cos(pitch), np.sin(roll), np.cos(roll)
    f = np.stack([sy * cp, cy * cp, sp], axis=1)
    r = np.stack([cy, -sy, np.zeros_like(sy)], axis=1)
    u = np.cross(r, f)
    r2 = cr[:, None] * r - sr[:, None] * u
    u2 = sr[:, None] * r + cr[:, None] * u
    return np.stack([r2, -u2, f], axis=1), r, f


def rotation_to_quaternion(rot: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3) to unit quaternions (w, x, y, z) with w >= 0 (the largest-pivot formulas)."""
    m = np.asarray(rot, np.float64).reshape(-1, 3, 3)
    m00, m01, m02 = m[:, 0, 0], m[:, 0, 1], m[:, 0, 2]
    m10, m11, m12 = m[:, 1, 0], m[:, 1, 1], m[:, 1, 2]
    m20, m21, m22 = m[:, 2, 0], m[:, 2, 1], m[:, 2, 2]
    tr = m00 + m11 + m22
    cases = [  # (pivot, w, x, y, z) with s = 2 sqrt(1 + pivot)
        (tr, lambda s: s / 4, lambda s: (m21 - m12) / s, lambda s: (m02 - m20) / s, lambda s: (m10 - m01) / s),
        (m00 - m11 - m22, lambda s: (m21 - m12) / s, lambda s: s / 4, lambda s: (m01 + m10) / s,
         lambda s: (m02 + m20) / s),
        (m11 - m00 - m22, lambda s: (m02 - m20) / s, lambda s: (m01 + m10) / s, lambda s: s / 4,
         lambda s: (m12 + m21) / s),
        (m22 - m00 - m11, lambda s: (m10 - m01) / s, lambda s: (m02 + m20) / s, lambda s: (m12 + m21) / s,
         lambda s: s / 4),
    ]
    pick = np.argmax(np.stack([c[0] for c in cases]), axis=0)
    q = np.zeros((m.shape[0], 4))
    for i, (pivot, *parts) in enumerate(cases):
        sel = pick == i
        if sel.any():
            s = 2.0 * np.sqrt(np.maximum(1.0 + pivot, 1e-300))
            q[sel] = np.stack([f(s) for f in parts], axis=1)[sel]
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def rotation_vector_to_matrix(rotvec: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation vectors (..., 3) in radians to rotation matrices (..., 3, 3)."""
    v = np.asarray(rotvec, np.float64)
    theta = np.linalg.norm(v, axis=-1, keepdims=True)
    small = theta < 1e-12
    axis = np.where(small, 0.0, v / np.where(small, 1.0, theta))
    x, y, z = axis[..., 0], axis[..., 1], axis[..., 2]
    zero = np.zeros_like(x)
    k = np.stack([np.stack([zero, -z, y], -1), np.stack([z, zero, -x], -1), np.stack([-y, x, zero], -1)], -2)
    th = theta[..., None]
    eye = np.broadcast_to(np.eye(3), k.shape)
    return eye + np.sin(th) * k + (1.0 - np.cos(th)) * (k @ k)


def row_poses(camera: Camera, row_times_ns: np.ndarray) -> Kinematics:
    """Ground truth of a frame: the camera's kinematics at every line's sample time (``Frame.row_times_ns``)."""
    return Trajectory(camera).at_ns(np.asarray(row_times_ns, np.int64))
