"""The emulated camera's IMU over HTTP: ``GET /imu.jsonl``, one JSON object per sample, as they are made.

Each line is ``{"t_ns": T, "gyro": [wx, wy, wz], "accel": [ax, ay, az]}`` (device-clock ns, rad/s, m/s^2,
IMU axes); the first line is ``{"imu": {...}}``, the IMU's calibration (rate, Kalibr noise terms, ``T_cam_imu``,
``time_offset_ns``). ``?from_ns=T`` starts at a device time still in the IMU buffer (default: now), ``?samples=N``
ends the response after N samples (default: endless). The stream follows the device clock, written every
``POLL_S``; a client that does not read within ``SEND_TIMEOUT_S`` is dropped, and at most ``MAX_STREAMS`` IMU
streams are served at once (HTTP 503 beyond), so no reader can grow the server's memory or stall it.
"""

from __future__ import annotations

import asyncio
import json
from typing import Any

from aiohttp import web
from rollcam.common.errors import ConfigError, DeviceError
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.imu import device_samples

IMU_PATH = "/imu.jsonl"
POLL_S = 0.02
SEND_TIMEOUT_S = 5.0
MAX_STREAMS = 8
MAX_BATCH = 4096


def _calibration(camera: FirmwareCamera) -> dict[str, Any]:
    p = camera.spec.imu
    assert p is not None
    return {"imu": {"rate_hz": p.rate_hz, "gyroscope_noise_density": p.gyroscope_noise_density,
                    "gyroscope_random_walk": p.gyroscope_random_walk,
                    "accelerometer_noise_density": p.accelerometer_noise_density,
                    "accelerometer_random_walk": p.accelerometer_random_walk,
                    "T_cam_imu": p.T_cam_imu.tolist(), "time_offset_ns": p.time_offset_ns}}


def query_int(request: web.Request, name: str) -> int | None:
    """Query option ``name`` as an integer >= 0, None when absent (HTTP 400 naming it when bad)."""
    text = request.query.get(name)
    if text is None:
        return None
    try:
        value = int(text)
    except ValueError:
        raise web.HTTPBadRequest(text=f"{name}={text!r} is not an integer") from None
    if value < 0:
        raise web.HTTPBadRequest(text=f"{name}={text!r} must be >= 0")
    return value


class ImuStreams:
    """The ``/imu.jsonl`` handler of one camera, bounded to ``MAX_STREAMS`` readers."""

    def __init__(self, camera: FirmwareCamera) -> None:
        self.camera = camera
        self.active = 0
        self.served = 0

    def add_to(self, app: web.Application) -> None:
        """Register the route on an aiohttp application."""
        app.router.add_get(IMU_PATH, self.handle, allow_head=False)

    async def handle(self, request: web.Request) -> web.StreamResponse:
        """Stream the IMU as JSON lines until the client leaves or ``samples=N`` are sent."""
        spec = getattr(self.camera, "spec", None)  # a host source behind ``rollcam view`` has no device spec
        if spec is None:
            raise web.HTTPNotFound(text="this source has no IMU")
        if spec.imu is None:
            raise web.HTTPNotFound(text="the IMU is off (imu=on turns it on)")
        limit = query_int(request, "samples")
        start = query_int(request, "from_ns")
        if self.active >= MAX_STREAMS:
            raise web.HTTPServiceUnavailable(text=f"{MAX_STREAMS} IMU streams already", headers={"Retry-After": "1"})
        self.active += 1
        self.served += 1
        try:
            return await self._stream(request, limit, start)
        finally:
            self.active -= 1

    async def _stream(self, request: web.Request, limit: int | None, start: int | None) -> web.StreamResponse:
        resp = web.StreamResponse(headers={"Content-Type": "application/x-ndjson", "Cache-Control": "no-store"})
        await resp.prepare(request)
        t = self.camera.clock_ns() if start is None else start
        sent = 0
        try:
            await asyncio.wait_for(resp.write((json.dumps(_calibration(self.camera)) + "\n").encode()),
                                   SEND_TIMEOUT_S)
            while limit is None or sent < limit:
                want = MAX_BATCH if limit is None else min(MAX_BATCH, limit - sent)
                try:
                    s = device_samples(self.camera, t, want)
                except (ConfigError, DeviceError) as exc:  # the IMU turned off, or the reader fell behind
                    await resp.write((json.dumps({"error": str(exc)}) + "\n").encode())
                    break
                if len(s):
                    lines = "".join(json.dumps({"t_ns": r[0], "gyro": r[1:4], "accel": r[4:7]}) + "\n"
                                    for r in s.to_rows())
                    await asyncio.wait_for(resp.write(lines.encode()), SEND_TIMEOUT_S)
                    sent += len(s)
                    t = int(s.t_ns[-1]) + 1
                else:
                    await asyncio.sleep(POLL_S)
            await resp.write_eof()
        except (ConnectionError, RuntimeError, asyncio.TimeoutError):  # gone, or not reading
            pass
        return resp
