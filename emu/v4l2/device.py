"""The emulated V4L2 camera as an application sees it: ``Device``, a thin class over the functions.

    from rollcam.emu.v4l2 import Device

    with Device.open("imx219", scene={"scene": "street"}) as cam:
        cam.set_format(1920, 1080, "YUYV")
        cam.controls["vblank"].value = 1000            # longer frame: lower frame rate, wider exposure range
        for buf in cam.stream(buffers=4, frames=10):
            print(buf.sequence, buf.timestamp_ns, buf.bytesused, buf.image().shape)
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.common.faults import FaultPlan
from rollcam.common.lifecycle import Closeable
from rollcam.firmware.camera import Clock, FirmwareCamera
from rollcam.firmware.pixfmt import is_raw
from rollcam.sim.codecs import Levels, codec

from . import functions as fn
from . import raw
from .ctrls import CID_TO_CONTROL
from .driver import EmuDriver


@dataclass(frozen=True)
class CapturedBuffer:
    """One dequeued buffer's bytes (a copy) and metadata; ``levels``: the sensor's, for a raw buffer's preview."""

    sequence: int
    timestamp_ns: int
    bytesused: int
    flags: int
    fourcc: str
    width: int
    height: int
    data: np.ndarray = field(repr=False)
    levels: Levels | None = field(default=None, repr=False)
    metadata: dict[str, Any] | None = field(default=None, repr=False)  # the metadata node's buffer of this frame

    @property
    def error(self) -> bool:
        """True when the driver flagged the buffer V4L2_BUF_FLAG_ERROR."""
        return bool(self.flags & raw.BufFlag.ERROR)

    @property
    def raw(self) -> bool:
        """True when the buffer holds raw sensor samples (Bayer or mono, unpacked or CSI-2 packed)."""
        return is_raw(self.fourcc)

    def samples(self) -> np.ndarray:
        """A raw buffer's samples as ``uint16 (H, W)`` at the format's bit depth (CSI-2 unpacked)."""
        if not self.raw:
            raise ConfigError(f"buffer format {self.fourcc!r} is not a raw sensor format")
        return codec(self.fourcc).decode(self.data, self.width, self.height)

    def image(self) -> np.ndarray:
        """The buffer's preview, 8-bit BGR (``rollcam.sim.codecs``: a raw buffer through the preview ISP, less
        the sensor's black level; GREY as a grey picture)."""
        return codec(self.fourcc).preview(self.data, self.width, self.height, self.levels)


class ControlHandle:
    """One control of a Device by name: ``.value`` reads and writes it, ``.info`` is its QUERYCTRL."""

    def __init__(self, device: Device, cid: int) -> None:
        self.device, self.id = device, cid

    @property
    def info(self) -> raw.QueryCtrl:
        """VIDIOC_QUERYCTRL of the control (range as it is now)."""
        return fn.query_control(self.device.driver, self.id)

    @property
    def value(self) -> int:
        """Current value."""
        return fn.get_control(self.device.driver, self.id)

    @value.setter
    def value(self, v: int) -> None:
        fn.set_control(self.device.driver, self.id, v)

    def __repr__(self) -> str:
        i = self.info
        return f"<control {i.name!r} = {self.value} [{i.minimum}..{i.maximum}]>"


class Device(Closeable):
    """An open emulated /dev/videoN: format, controls, buffers and streaming; a context manager."""

    def __init__(self, driver: EmuDriver) -> None:
        self.driver = driver
        self.controls = {name: ControlHandle(self, int(cid)) for cid, name in CID_TO_CONTROL.items()}

    @classmethod
    def open(cls, sensor: str, *, scene: dict[str, Any] | None = None, realtime: bool = True, bands: int = 8,
             faults: FaultPlan | str | None = None, clock: Clock | None = None, rt_priority: int | None = None,
             **camera_options: Any) -> Device:
        """A device on a new FirmwareCamera of ``sensor`` (``realtime=False``: frames as fast as asked;
        ``faults``: a ``FaultPlan`` or its text, e.g. ``"drop=5%,error=2%,seed=1"``; ``rt_priority``: the
        real-time pump's waits run under SCHED_FIFO at that priority)."""
        if "insensor" in camera_options:  # a network spec, as the option table takes it
            camera_options["insensor_values"] = {"insensor": camera_options.pop("insensor")}
        camera = FirmwareCamera(sensor, scene=scene, clock=clock, **camera_options)
        return cls(EmuDriver(camera, realtime=realtime, bands=bands, faults=faults, rt_priority=rt_priority))

    def __repr__(self) -> str:
        f = self.driver.fmt
        return (f"<emulated V4L2 device {self.driver.camera.sensor.name} {f.width}x{f.height} {f.pixelformat}"
                f"{' streaming' if self.driver.queue.streaming else ''}{' closed' if self.closed else ''}>")

    def _close(self) -> None:
        """Stop streaming and free the buffers."""
        self.driver.close()

    @property
    def info(self) -> raw.Capability:
        """VIDIOC_QUERYCAP."""
        return fn.querycap(self.driver)

    def set_format(self, width: int, height: int, fourcc: str = "YUYV") -> raw.PixFormat:
        """VIDIOC_S_FMT; returns the format set (rounded like TRY_FMT)."""
        return fn.set_format(self.driver, width, height, fourcc)

    def stream(self, buffers: int = 4, frames: int | None = None, timeout_s: float | None = 5.0,
               metadata: bool = False) -> Iterator[CapturedBuffer]:
        """REQBUFS, QBUF all, STREAMON, then DQBUF/copy/QBUF; stops after ``frames`` (STREAMOFF, REQBUFS 0).
        ``metadata``: stream the metadata node too (a camera with an in-sensor network), each buffer's
        ``metadata`` the ``RCIS`` buffer of the same sequence (``meta.unpack``), None when it was lost."""
        d = self.driver
        meta = self._metadata_node() if metadata else None
        n = fn.request_buffers(d, buffers)
        try:
            if meta is not None:
                for i in range(fn.request_buffers(meta, buffers)):
                    fn.queue_buffer(meta, i)
                fn.stream_on(meta)
            for i in range(n):
                fn.queue_buffer(d, i)
            fn.stream_on(d)
            count = 0
            while frames is None or count < frames:
                buf, view = fn.dequeue_buffer(d, timeout_s=timeout_s)
                f = d.fmt
                levels = Levels.of_sensor(d.camera.sensor) if is_raw(f.pixelformat) else None
                out = CapturedBuffer(buf.sequence, buf.timestamp_ns, buf.bytesused, buf.flags, f.pixelformat,
                                     f.width, f.height, view.copy(), levels, _metadata_of(meta, buf.sequence))
                fn.queue_buffer(d, buf.index)
                count += 1
                yield out
        finally:
            if not d.queue.disconnected:
                fn.stream_off(d)
                fn.request_buffers(d, 0)
            if meta is not None:
                meta.close()

    def _metadata_node(self) -> Any:
        from .meta import MetaDriver

        if self.driver.camera.spec.insensor is None:
            raise ConfigError("metadata=True needs a camera with an in-sensor network (insensor=..., e.g. "
                              "Device.open('imx219', insensor='personnet-raw'))")
        return self.driver.meta or MetaDriver(self.driver)


def _metadata_of(meta: Any, sequence: int) -> dict[str, Any] | None:
    """The metadata node's buffer of ``sequence`` (filled as the image buffer completed), re-queued."""
    from .meta import unpack
    from .queue import V4L2Error

    while meta is not None:
        try:
            buf, view = fn.dequeue_buffer(meta, block=False)
        except V4L2Error:
            return None  # none done: that frame's metadata was lost
        doc = unpack(view.tobytes())
        fn.queue_buffer(meta, buf.index)
        if buf.sequence >= sequence:
            return doc if buf.sequence == sequence else None
    return None
