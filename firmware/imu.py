"""The emulated camera's IMU: its options resolved against the hw_config, and which samples each frame carries.

The IMU is part of the camera's spec (``CameraSpec.imu``: ``rollcam.sim.imu.ImuParams`` or None): the
hw_config's ``imu`` section, else the model's defaults, with the ``imu_*`` options of the one option table
on top (any of them turns the IMU on; ``imu=off`` turns it off). ``FrameImu`` decides which samples a frame
carries: those stamped since the previous frame's end of readout up to this frame's (the last line's end of
exposure), so consecutive frames partition the IMU stream with no sample lost or repeated, and a stream's
first frame carries one frame period's worth. A frame made again for the same plan (a GS/RS pair) carries
the same samples.
"""

from __future__ import annotations

import dataclasses
import threading
from typing import Any

from rollcam.sim.hwconfig import SensorConfig
from rollcam.sim.imu import Imu, ImuParams, ImuSamples
from rollcam.sim.pose import Trajectory

IMU_FIELDS = {
    "imu_rate": "rate_hz",
    "imu_gyro_noise": "gyroscope_noise_density",
    "imu_gyro_walk": "gyroscope_random_walk",
    "imu_accel_noise": "accelerometer_noise_density",
    "imu_accel_walk": "accelerometer_random_walk",
    "imu_offset_us": "time_offset_ns",
    "imu_rotation_deg": "rotation_cam_imu_deg",
    "imu_translation_m": "translation_cam_imu_m",
}
"""Option name -> ``ImuParams`` field."""
IMU_OPTIONS = {"imu", *IMU_FIELDS}


def resolve_imu(sensor: SensorConfig, current: ImuParams | None, values: dict[str, Any]) -> ImuParams | None:
    """The IMU after ``values`` (parsed ``imu``/``imu_*`` options) are applied to ``current``."""
    if values.get("imu") is False:
        return None
    changes = {IMU_FIELDS[k]: v for k, v in values.items() if k in IMU_FIELDS}
    if not changes and not values.get("imu") and current is None:
        return None
    if "time_offset_ns" in changes:
        changes["time_offset_ns"] = round(changes["time_offset_ns"] * 1000)
    base = current or sensor.imu or ImuParams()
    return dataclasses.replace(base, **changes)


def imu_option_values(sensor: SensorConfig, imu: ImuParams | None) -> dict[str, Any]:
    """The ``imu``/``imu_*`` options in effect (an IMU that is off shows the figures it would have)."""
    p = imu or sensor.imu or ImuParams()
    out: dict[str, Any] = {"imu": imu is not None}
    for name, fld in IMU_FIELDS.items():
        value = getattr(p, fld)
        out[name] = value / 1000 if fld == "time_offset_ns" else value
    return out


def frame_end_ns(spec: Any, start_ns: int) -> int:
    """Device time the frame starting at ``start_ns`` ends: its last line's end of exposure."""
    s = spec.settings
    readout = int(s.timing.line_offset_ns(s.n_lines - 1)) if s.shutter == "rolling" else 0
    return int(start_ns) + readout + s.exposure_ns


class FrameImu:
    """Hands each frame its IMU samples (see the module docstring); one per device, thread-safe.

    The windows of the last few frames are kept by sequence number, because frames are made ahead of their
    time (``emu.pump``): a frame remade after a control change starts where the frame before it ends, and the
    frames made ahead after it are forgotten, so no sample is lost or repeated whatever was made ahead."""

    KEEP = 8
    """Windows remembered (more than the pump makes ahead)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._imu: tuple[Any, Imu] | None = None
        self._windows: dict[int, tuple[int, int, int]] = {}  # seq -> (start, window start, window end)

    def imu(self, spec: Any, camera: Any) -> Imu:
        """The IMU of ``spec`` on the scene camera ``camera`` (rebuilt when either changes)."""
        key = (spec.imu, spec.noise_seed, camera)
        if self._imu is None or self._imu[0] != key:
            self._imu = (key, Imu(spec.imu, Trajectory(camera), seed=spec.noise_seed))
        return self._imu[1]

    def samples(self, spec: Any, camera: Any, seq: int, start_ns: int) -> ImuSamples:
        """The samples frame ``seq`` starting at ``start_ns`` carries."""
        end = frame_end_ns(spec, start_ns)
        with self._lock:
            same = self._windows.get(seq)
            before = self._windows.get(seq - 1)
            if same is not None and same[0] == start_ns:
                t0, end = same[1], same[2]
            elif before is not None and before[2] <= end:
                t0 = before[2]
            else:
                t0 = end - spec.settings.timing.frame_period_ns
            # A frame (re)made at seq invalidates what was made ahead after it.
            self._windows = {k: v for k, v in self._windows.items() if seq - self.KEEP < k < seq}
            self._windows[seq] = (int(start_ns), t0, end)
            imu = self.imu(spec, camera)
        return imu.samples(t0, end)

    def reset(self) -> None:
        """Forget the frames made (a new stream starts its first frame afresh)."""
        with self._lock:
            self._windows = {}


def with_imu(frame: Any, spec: Any, camera: Any, tap: FrameImu, seq: int, start_ns: int) -> Any:
    """``frame`` with its IMU samples, per-line true poses and, with ``rs_correct=gyro``, the ISP's gyro
    correction applied (the device's own IMU over the frame's lines; the reference is the first line read)."""
    from rollcam.sim.pose import row_poses

    samples = tap.samples(spec, camera, seq, start_ns)
    times = frame.row_times_ns
    poses = row_poses(camera, times)
    k = intrinsics(camera)
    meta = {**frame.meta, "intrinsics": list(k)}
    data = frame.data
    if spec.rs_correct == "gyro":
        from rollcam.sim.rscorrect import correct_image

        p = spec.imu
        margin = 2 * (10**9 // p.rate_hz)
        cover = tap.imu(spec, camera).samples(int(times.min()) + p.time_offset_ns - margin,
                                              int(times.max()) + p.time_offset_ns + margin)
        data, _ = correct_image(frame.data, cover, times, int(times.min()), k,
                                by_column=frame.readout.by_column)
        meta["rs_correct"] = "gyro"
    return dataclasses.replace(frame, data=data, imu=samples, poses=poses, meta=meta)


def intrinsics(camera: Any) -> tuple[float, float, float, float]:
    """Pinhole ``(fx, fy, cx, cy)`` of a scene camera in OpenCV's convention (pixel centres at integers)."""
    return (float(camera.fx_px), float(camera.fx_px), camera.width / 2.0 - 0.5, camera.height / 2.0 - 0.5)


IMU_BUFFER_NS = 2 * 10**9
"""How far back the device's IMU buffer reaches (a reader asking for older samples is refused)."""


def device_samples(camera: Any, t0_ns: int, limit: int, now_ns: int | None = None) -> ImuSamples:
    """At most ``limit`` samples of ``camera``'s IMU stamped from ``t0_ns`` up to its device clock now (the
    serial ``IMU?`` command and the HTTP ``/imu.jsonl`` stream); DeviceError when the IMU is off, ConfigError
    for a start older than the buffer (``IMU_BUFFER_NS``)."""
    from rollcam.common.errors import ConfigError, DeviceError

    spec = camera.spec
    if spec.imu is None:
        raise DeviceError("the IMU is off (imu=on turns it on)")
    now = camera.clock_ns() if now_ns is None else int(now_ns)
    if t0_ns < now - IMU_BUFFER_NS:
        raise ConfigError(f"IMU samples from {t0_ns} ns are gone: the buffer holds the last "
                          f"{IMU_BUFFER_NS // 10**6} ms (from {now - IMU_BUFFER_NS} ns)")
    imu = camera.imager.imu.imu(spec, camera.synthetic.camera)
    idx = imu.indices(t0_ns, now)
    end = spec.imu.stamp_ns(idx.start + limit) if len(idx) > limit else now
    return imu.samples(t0_ns, end)
