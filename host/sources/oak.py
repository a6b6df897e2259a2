"""``oak:[MXID][?socket=CAM_A&size=WxH&fps=..&exposure_us=..&gain=..&sensor=..&frames=..]`` -- a Luxonis OAK.

Through depthai v3: a pipeline on the device (the first available, or the one whose device id / MXID is
given) with a ``Camera`` node on ``socket`` and one ``requestOutput`` (BGR, ``size``, ``fps``) read from its
output queue. Frames carry the device's sequence number, device timestamp and exposure time; ISO goes into
``meta``. depthai stamps an ImgFrame at the end of its exposure, so the Frame's start-of-exposure timestamp is
read with ``getTimestampDevice(CameraExposureOffset.START)`` (whole microseconds, as depthai keeps them).
Row timing: ``sensor=NAME``, else the socket's usual sensor (CAM_A: the IMX378 of OAK-1/OAK-D; CAM_B/CAM_C:
the OV9282 mono pair, global shutter, for which the closest hw_config is ``ov9281``). ``exposure_us``/``gain``
switch the camera to manual exposure (``CameraControl.setManualExposure``; gain 1.0 = ISO 100; both must be
positive, exposure at least 1 us); ``set_control`` changes either while streaming and keeps the other. Every
option is checked before the device is opened.
"""

from __future__ import annotations

import datetime
import importlib
import math
import os
import sys
from typing import Any

import numpy as np
from rollcam.common.errors import DeviceError, DeviceNotFoundError, MissingDependencyError, SourceError
from rollcam.sim.frame import Frame

from .base import CameraSource, SourceURI, finite_float, positive_float, positive_int
from .rowtiming import FrameTimer

OPTIONS = {"socket", "size", "fps", "exposure_us", "gain", "sensor", "frames", "timeout"}
DEFAULT_SENSOR = {"CAM_A": "imx378", "CAM_B": "ov9281", "CAM_C": "ov9281"}
"""Board socket -> hw_config of the sensor OAK cameras usually carry there."""
DEFAULT_SIZE = (1920, 1080)
ISO_PER_GAIN = 100
DEFAULT_EXPOSURE_US = 10_000.0
"""Manual exposure used when only ``gain`` is given."""


DEPTHAI_LOG_LEVEL = "error"
"""depthai's log level while rollcam imports it (its own ``DEPTHAI_LEVEL`` wins when set): its start-up
warnings (``USB protocol not available`` in a container, ...) are noise to a user of ``rollcam list``."""


def _import_quietly(name: str) -> Any:
    """Import ``name`` with depthai's logger at ``DEPTHAI_LOG_LEVEL`` and file descriptor 1 pointed at stderr:
    what it still prints at start-up must not corrupt JSON output such as ``rollcam list --json``."""
    if name in sys.modules:
        return importlib.import_module(name)
    sys.stdout.flush()
    saved = os.dup(1)
    set_level = "DEPTHAI_LEVEL" not in os.environ
    if set_level:  # read once, when depthai loads; removed again so child processes see the user's environment
        os.environ["DEPTHAI_LEVEL"] = DEPTHAI_LOG_LEVEL
    try:
        os.dup2(2, 1)
        return importlib.import_module(name)
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        if set_level:
            os.environ.pop("DEPTHAI_LEVEL", None)


def import_depthai() -> Any:
    """The depthai module (v3), or a MissingDependencyError naming what to install."""
    try:
        dai = _import_quietly("depthai")
    except ImportError as exc:
        if exc.name is not None and exc.name.split(".")[0] != "depthai":
            raise
        raise MissingDependencyError("depthai", feature="the oak: source") from None
    version = getattr(dai, "__version__", "0")
    if not str(version).split(".")[0].isdigit() or int(str(version).split(".")[0]) < 3:
        raise MissingDependencyError("depthai>=3,<4", feature=f"the oak: source (found depthai {version})")
    return dai


def timedelta_ns(value: datetime.timedelta) -> int:
    """A timedelta as whole ns (exact: timedelta holds days, seconds and microseconds as integers)."""
    return ((value.days * 86_400 + value.seconds) * 1_000_000 + value.microseconds) * 1000


def device_ids(dai: Any) -> list[str]:
    """Ids (MXIDs) of the OAK devices depthai can see."""
    return [d.getDeviceId() for d in dai.Device.getAllAvailableDevices()]


class OakSource(CameraSource):
    """Frames of one OAK camera socket through a depthai v3 pipeline."""

    def __init__(self, uri: SourceURI, dai: Any | None = None) -> None:
        self.uri = uri.uri
        uri.take(set(), OPTIONS)
        self.dai = dai = dai or import_depthai()
        socket = uri.get("socket", str, "CAM_A").upper()
        if not hasattr(dai.CameraBoardSocket, socket):
            raise SourceError(f"source {uri.uri!r}: option socket={socket!r} is not a board socket (CAM_A..CAM_D)")
        from .base import parse_size

        self.size = uri.get("size", parse_size, DEFAULT_SIZE)
        self.fps = uri.get("fps", finite_float)
        self.limit = uri.get("frames", positive_int)
        self.timeout_s = uri.get("timeout", finite_float, 5.0)
        self.timer = FrameTimer(uri.get("sensor", str, DEFAULT_SENSOR.get(socket)), uri.uri)
        exposure_us = uri.get("exposure_us", positive_float)
        gain = uri.get("gain", positive_float)
        self._manual: dict[str, float] | None = None  # last manual exposure/gain, kept by set_control
        if exposure_us is not None or gain is not None:
            self._check_manual(exposure_us or DEFAULT_EXPOSURE_US, gain or 1.0)
        self.index = 0
        self.device = self._open_device(uri)
        try:
            self.pipeline = dai.Pipeline(self.device)
            self.camera = self.pipeline.create(dai.node.Camera).build(getattr(dai.CameraBoardSocket, socket))
            out = self.camera.requestOutput(self.size, dai.ImgFrame.Type.BGR888i, fps=self.fps)
            self.queue = out.createOutputQueue(maxSize=4, blocking=False)
            self.control_queue = self.camera.inputControl.createInputQueue()
            self.pipeline.start()
        except Exception as exc:  # depthai raises RuntimeError subclasses for device-side failures
            self.device.close()
            raise DeviceError(f"source {uri.uri!r}: the OAK pipeline failed to start ({exc})") from None
        if exposure_us is not None or gain is not None:
            self.set_exposure(exposure_us or DEFAULT_EXPOSURE_US, gain or 1.0)

    def _open_device(self, uri: SourceURI) -> Any:
        dai = self.dai
        available = dai.Device.getAllAvailableDevices()
        if not available:
            raise DeviceNotFoundError(f"source {uri.uri!r}: no OAK device found; plug one in (USB3 cable, or on the "
                                      "same network for PoE models) and check 'rollcam list'")
        if uri.target:
            match = [d for d in available if d.getDeviceId() == uri.target]
            if not match:
                ids = [d.getDeviceId() for d in available]
                raise DeviceNotFoundError(f"source {uri.uri!r}: no OAK with id {uri.target!r}; available: {ids}")
            info = match[0]
        else:
            info = available[0]
        try:
            return dai.Device(info)
        except Exception as exc:
            raise DeviceError(f"source {uri.uri!r}: cannot open OAK {info.getDeviceId()!r} ({exc}); is another "
                              "program using it?") from None

    def _check_manual(self, exposure_us: float, gain: float) -> tuple[int, int]:
        """The whole-us exposure and ISO that ``setManualExposure`` takes; a SourceError when out of range."""
        exposure, iso = round(exposure_us), round(gain * ISO_PER_GAIN)
        if not math.isfinite(exposure_us) or exposure < 1:
            raise SourceError(f"source {self.uri!r}: exposure_us={exposure_us!r} is invalid (at least 1 us)")
        if not math.isfinite(gain) or iso < 1:
            raise SourceError(f"source {self.uri!r}: gain={gain!r} is invalid (at least {1 / ISO_PER_GAIN:g})")
        return exposure, iso

    def set_exposure(self, exposure_us: float, gain: float = 1.0) -> None:
        """Manual exposure (us) and analogue gain (1.0 = ISO 100) through the camera's control input."""
        exposure, iso = self._check_manual(float(exposure_us), float(gain))
        ctrl = self.dai.CameraControl()
        ctrl.setManualExposure(exposure, iso)
        self.control_queue.send(ctrl)
        self._manual = {"exposure_us": float(exposure_us), "gain": float(gain)}

    def set_control(self, name: str, value: float) -> bool:
        """``exposure_us`` or ``gain`` while streaming (the other keeps its last manual value); ``auto`` resumes AE."""
        if name == "auto":
            ctrl = self.dai.CameraControl()
            ctrl.setAutoExposureEnable()
            self.control_queue.send(ctrl)
            return True
        if name not in ("exposure_us", "gain"):
            raise SourceError(f"source {self.uri!r}: unknown control {name!r}; known: ['auto', 'exposure_us', 'gain']")
        current = dict(self._manual or {"exposure_us": DEFAULT_EXPOSURE_US, "gain": 1.0})
        current[name] = float(value)
        self.set_exposure(current["exposure_us"], current["gain"])
        return True

    def read(self) -> Frame | None:
        """The next frame from the device (None after ``frames=N``)."""
        self._check_open()
        if self.limit is not None and self.index >= self.limit:
            return None
        msg = self.queue.get(datetime.timedelta(seconds=self.timeout_s))
        if msg is None:
            raise DeviceError(f"source {self.uri!r}: no frame from the OAK within {self.timeout_s:g} s")
        image = np.asarray(msg.getCvFrame())
        # The no-argument getter is the END of exposure; a Frame's timestamp is its start of exposure.
        start = msg.getTimestampDevice(self.dai.CameraExposureOffset.START)
        frame = self.timer.frame(image, "BGR3" if image.ndim == 3 else "GREY", msg.getSequenceNum(),
                                 timedelta_ns(start), timedelta_ns(msg.getExposureTime()),
                                 meta={"iso": int(msg.getSensitivity())})
        self.index += 1
        return frame

    def _close(self) -> None:
        """Stop the pipeline and release the device."""
        try:
            self.pipeline.stop()
        finally:
            self.device.close()

    def info(self) -> dict[str, Any]:
        """Device id, size, fps and row timing."""
        return {"uri": self.uri, "device": self.device.getDeviceId() if hasattr(self.device, "getDeviceId") else None,
                "width": self.size[0], "height": self.size[1], "fps": self.fps, **self.timer.timing.to_json()}


def open_source(uri: SourceURI) -> OakSource:
    """Scheme entry point for ``oak:``."""
    return OakSource(uri)
