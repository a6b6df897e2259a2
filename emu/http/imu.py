"""The emulated camera's IMU over HTTP: ``GET /imu.jsonl``, one JSON object per sample, as they are made.

Each line is ``{"t_ns": T, "gyro": [wx, wy, wz], "accel": [ax, ay, az]}`` (device-clock ns, rad/s, m/s^2,
IMU axes); the first line is ``{"imu": {...}}``, the IMU's calibration (rate, Kalibr noise terms, ``T_cam_imu``,
``time_offset_ns``). ``?from_ns=T`` starts at a device time still in the IMU buffer (default: now), ``?samples=N``
ends the response after N samples (default: endless). The stream follows the device clock, polled every
20 ms, and is bounded as every JSON-lines endpoint is (emu/http/jsonl.py): fair slots as for the MJPEG streams
(a per-address cap, an idle or non-reading reader evicted for a newcomer and closed after a deadline), so no
reader can grow the server's memory, stall it or lock the others out.
"""

from __future__ import annotations

from typing import Any, ClassVar

from aiohttp import web
from rollcam.common.values import non_negative_int
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.imu import device_samples

from .jsonl import JsonLinesStreams, query_option

IMU_PATH = "/imu.jsonl"
MAX_BATCH = 4096


def _calibration(camera: FirmwareCamera) -> dict[str, Any]:
    p = camera.spec.imu
    assert p is not None
    return {"imu": {"rate_hz": p.rate_hz, "gyroscope_noise_density": p.gyroscope_noise_density,
                    "gyroscope_random_walk": p.gyroscope_random_walk,
                    "accelerometer_noise_density": p.accelerometer_noise_density,
                    "accelerometer_random_walk": p.accelerometer_random_walk,
                    "T_cam_imu": p.T_cam_imu.tolist(), "time_offset_ns": p.time_offset_ns}}


class ImuStreams(JsonLinesStreams):
    """The ``/imu.jsonl`` handler of one camera, its readers held in fair slots (emu/http/jsonl.py)."""

    path: ClassVar[str] = IMU_PATH
    what: ClassVar[str] = "IMU"
    limit_option: ClassVar[str] = "samples"

    def open(self, request: web.Request) -> dict[str, int]:
        """The stream's next sample time: ``?from_ns`` or now."""
        spec = getattr(self.camera, "spec", None)  # a host source behind ``rollcam view`` has no device spec
        if spec is None:
            raise web.HTTPNotFound(text="this source has no IMU")
        if spec.imu is None:
            raise web.HTTPNotFound(text="the IMU is off (imu=on turns it on)")
        start = query_option(request, "from_ns", non_negative_int)
        return {"t": self.camera.clock_ns() if start is None else start}

    def header(self) -> dict[str, Any]:
        """The IMU's calibration."""
        return _calibration(self.camera)

    def take(self, cursor: dict[str, int], most: int | None) -> list[dict[str, Any]]:
        """The samples made from the cursor's time on (ConfigError/DeviceError: the IMU turned off, or the reader
        fell behind the buffer)."""
        s = device_samples(self.camera, cursor["t"], MAX_BATCH if most is None else min(MAX_BATCH, most))
        if len(s):
            cursor["t"] = int(s.t_ns[-1]) + 1
        return [{"t_ns": r[0], "gyro": r[1:4], "accel": r[4:7]} for r in s.to_rows()]
