"""A stand-in for the depthai v3 device API, backed by emulated sensors, for tests without an OAK.

It covers what a typical OAK capture script touches: ``Device.getAllAvailableDevices``, ``Device(info)``,
``DeviceInfo.getDeviceId``, ``Pipeline()`` / ``Pipeline(device)`` (context manager, ``create``, ``start``,
``isRunning``, ``stop``), ``node.Camera`` (``build(socket)``, ``requestOutput(size, type, fps=..)``,
``requestFullResolutionOutput``, ``inputControl.createInputQueue``), ``Output.createOutputQueue`` and
``MessageQueue`` (``get``, ``tryGet``, ``has``), ``ImgFrame`` (``getCvFrame``, ``getFrame``,
``getSequenceNum``, ``getTimestamp(Device)`` with an optional ``CameraExposureOffset``, ``getExposureTime``,
``getSensitivity``, ``getWidth``, ``getHeight``, ``getType``) and ``CameraControl``
(``setManualExposure``, ``setAutoExposureEnable``). Frames are rendered on demand (no threads) by an
``emu:`` camera of each device's socket, so their timestamps, exposure and sequence numbers are the
emulator's; as on a real OAK, an ImgFrame is stamped at the END of its exposure (whole microseconds of
exposure, as depthai keeps them), and ``getTimestamp(Device)(CameraExposureOffset.START)`` gives the start
(the emulator's ``timestamp_ns``). ``MockDevice.frames`` ends the stream: the pipeline stops and ``get`` raises
``QueueClosed``, as depthai's queues do when a pipeline ends. Anything outside this surface is absent, so a
script that needs more fails loudly with AttributeError rather than silently getting a fake.
"""

from __future__ import annotations

import datetime
import enum
import types
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from rollcam.sim.codecs import codec, preview_frame

__version__ = "3.0.0+rollcam.mock"

DEFAULT_SENSORS = {"CAM_A": "imx378", "CAM_B": "ov9281", "CAM_C": "ov9281"}


class QueueClosed(RuntimeError):
    """``MessageQueue`` read after its pipeline stopped (depthai raises ``QueueException``)."""


CameraBoardSocket = enum.Enum("CameraBoardSocket", [f"CAM_{c}" for c in "ABCDEFGH"] + ["AUTO"])
CameraExposureOffset = enum.Enum("CameraExposureOffset", ["START", "MIDDLE", "END"])


class _ImgType(enum.Enum):
    BGR888i = 10
    RGB888i = 11
    GRAY8 = 12
    NV12 = 13


def _td(ns: int) -> datetime.timedelta:
    return datetime.timedelta(microseconds=int(ns) // 1000)


class ImgFrame:
    """One image message: pixels plus the device's sequence number, timestamp and exposure."""

    Type = _ImgType

    def __init__(self) -> None:
        self._data = np.zeros((0, 0, 3), np.uint8)
        self._type = _ImgType.BGR888i
        self._seq, self._ts_ns, self._exp_ns, self._iso = 0, 0, 0, 100

    def stamp(self, seq: int, ts_ns: int, exp_ns: int, iso: int) -> None:
        """Set what the device stamps on a frame (the mock's own setter: depthai's host side has none for all)."""
        self._seq, self._ts_ns, self._exp_ns, self._iso = seq, ts_ns, exp_ns, iso

    def setCvFrame(self, image: np.ndarray, type: _ImgType) -> None:
        """Set the pixels (BGR, grey) as depthai's ``setCvFrame`` does."""
        self._data, self._type = np.asarray(image), type

    def getCvFrame(self) -> np.ndarray:
        """BGR (or grey) pixels, as OpenCV wants them."""
        if self._type == _ImgType.RGB888i:
            return self._data[..., ::-1].copy()
        return self._data

    def getFrame(self) -> np.ndarray:
        """The pixels in their own type's layout."""
        return self._data

    def getWidth(self) -> int:
        return int(self._data.shape[1])

    def getHeight(self) -> int:
        return int(self._data.shape[0])

    def getType(self) -> _ImgType:
        return self._type

    def setSequenceNum(self, seq: int) -> None:
        self._seq = int(seq)

    def getSequenceNum(self) -> int:
        return self._seq

    def setTimestampDevice(self, value: datetime.timedelta) -> None:
        """Set the device timestamp, which (as in depthai) is the END of exposure."""
        self._ts_ns = int(value / datetime.timedelta(microseconds=1)) * 1000

    def _at(self, offset: CameraExposureOffset | None) -> datetime.timedelta:
        # depthai-core: START = ts - exposure, MIDDLE = ts - exposure / 2, END (and no offset) = ts.
        back = {None: 0, CameraExposureOffset.END: 0, CameraExposureOffset.MIDDLE: self._exp_ns // 2,
                CameraExposureOffset.START: self._exp_ns}
        return _td(self._ts_ns - back[offset])

    def getTimestampDevice(self, offset: CameraExposureOffset | None = None) -> datetime.timedelta:
        """Device-clock timestamp at ``offset`` of the exposure; without one, the end of exposure."""
        return self._at(offset)

    def getTimestamp(self, offset: CameraExposureOffset | None = None) -> datetime.timedelta:
        """Host-synced timestamp; the mock's host and device clocks are the same."""
        return self._at(offset)

    def getExposureTime(self) -> datetime.timedelta:
        return _td(self._exp_ns)

    def getSensitivity(self) -> int:
        return self._iso


class CameraControl:
    """A control message; the mock applies manual exposure/ISO and auto-exposure requests."""

    def __init__(self) -> None:
        self.exposure_us: int | None = None
        self.iso: int | None = None
        self.auto: bool = False

    def setManualExposure(self, exposure_us: int, iso: int) -> CameraControl:
        self.exposure_us, self.iso, self.auto = int(exposure_us), int(iso), False
        return self

    def setAutoExposureEnable(self) -> CameraControl:
        self.auto = True
        return self


@dataclass
class MockDevice:
    """One emulated OAK: its id, what each socket's sensor sees, and an optional frame limit."""

    device_id: str = "14442C10D13EABCE00"
    sensors: dict[str, str] = field(default_factory=lambda: dict(DEFAULT_SENSORS))
    scene: str = "street"
    seed: int = 0
    frames: int | None = None
    controls: list[CameraControl] = field(default_factory=list)
    opened: bool = False


class DeviceInfo:
    """What ``Device.getAllAvailableDevices`` lists."""

    def __init__(self, device: MockDevice | str = "") -> None:
        self._device = device if isinstance(device, MockDevice) else None
        self.deviceId = device.device_id if isinstance(device, MockDevice) else str(device)
        self.name = "1.1"
        self.state = "X_LINK_UNBOOTED"

    def getDeviceId(self) -> str:
        return self.deviceId


class MessageQueue:
    """Output queue of one camera output; frames are rendered when asked for."""

    def __init__(self, output: _Output) -> None:
        self._out = output

    def has(self) -> bool:
        return self._out.pipeline.isRunning()

    def tryGet(self) -> ImgFrame | None:
        return self._out.next_frame() if self._out.pipeline.isRunning() else None

    def get(self, timeout: datetime.timedelta | None = None) -> ImgFrame:
        if not self._out.pipeline.isRunning():
            raise QueueClosed("MessageQueue was closed")
        return self._out.next_frame()


class _InputQueue:
    def __init__(self, camera: _Camera) -> None:
        self._camera = camera

    def send(self, msg: CameraControl) -> None:
        self._camera.apply(msg)


class _Output:
    def __init__(self, camera: _Camera, size: tuple[int, int], type: _ImgType | None, fps: float | None) -> None:
        self.camera, self.pipeline = camera, camera.pipeline
        self.size, self.type, self.fps = (int(size[0]), int(size[1])), type or _ImgType.NV12, fps
        self.index = 0
        self._source: Any = None

    def createOutputQueue(self, maxSize: int = 16, blocking: bool = False) -> MessageQueue:
        return MessageQueue(self)

    def _open(self) -> Any:
        from rollcam.host.sources import open_camera

        dev, cam = self.pipeline.device_state, self.camera
        opts = {"scene": dev.scene, "seed": dev.seed, "size": f"{self.size[0]}x{self.size[1]}"}
        if self.fps:
            opts["fps"] = self.fps
        if cam.exposure_us is not None:
            opts["exposure_us"] = cam.exposure_us
            opts["gain"] = cam.iso / 100
        query = "&".join(f"{k}={v}" for k, v in opts.items())
        source = open_camera(f"emu:{cam.sensor}?{query}")
        source.index = self.index
        return source

    def next_frame(self) -> ImgFrame:
        if self._source is None or self.camera.changed:
            self.camera.changed = False
            self._source = self._open()
        frame = self._source.read()
        self.index += 1
        limit = self.pipeline.device_state.frames
        if limit is not None and self.index >= limit:
            self.pipeline.stop()
        out = {_ImgType.GRAY8: "GREY", _ImgType.RGB888i: "RGB3"}.get(self.type, "BGR3")
        img = codec(out).encode(preview_frame(frame))
        msg = ImgFrame()
        msg.setCvFrame(np.ascontiguousarray(img), self.type if self.type != _ImgType.NV12 else _ImgType.BGR888i)
        # A real OAK stamps the frame at the end of exposure and keeps the exposure in whole microseconds.
        exp_ns = frame.exposure_ns // 1000 * 1000
        msg.stamp(frame.sequence, frame.timestamp_ns + exp_ns, exp_ns, self.camera.iso)
        return msg


class _Camera:
    """``dai.node.Camera`` of the mock."""

    def __init__(self, pipeline: Pipeline) -> None:
        self.pipeline = pipeline
        self.sensor = ""
        self.exposure_us: int | None = None
        self.iso = 100
        self.changed = False
        self.inputControl = types.SimpleNamespace(createInputQueue=lambda *a, **k: _InputQueue(self))

    def build(self, boardSocket: Any = None, *args: Any, **kwargs: Any) -> _Camera:
        name = getattr(boardSocket, "name", None) or "CAM_A"
        name = "CAM_A" if name == "AUTO" else name
        sensors = self.pipeline.device_state.sensors
        if name not in sensors:
            raise RuntimeError(f"Camera on socket {name} not found on device (sockets: {sorted(sensors)})")
        self.sensor = sensors[name]
        return self

    def requestOutput(self, size: Sequence[int], type: _ImgType | None = None, resizeMode: Any = None,
                      fps: float | None = None, **kwargs: Any) -> _Output:
        if not self.sensor:
            self.build()
        return _Output(self, (size[0], size[1]), type, fps)

    def requestFullResolutionOutput(self, type: _ImgType | None = None, fps: float | None = None,
                                    **kwargs: Any) -> _Output:
        """The sensor's default mode, full size (the mock's stand-in for the full array)."""
        if not self.sensor:
            self.build()
        from rollcam.sim.hwconfig import load_sensor

        mode = load_sensor(self.sensor).mode()
        return _Output(self, (mode.width, mode.height), type, fps)

    def apply(self, ctrl: CameraControl) -> None:
        self.pipeline.device_state.controls.append(ctrl)
        if ctrl.auto:
            self.exposure_us, self.iso = None, 100
        elif ctrl.exposure_us is not None:
            self.exposure_us, self.iso = ctrl.exposure_us, ctrl.iso or 100
        self.changed = True


class Device:
    """``dai.Device``: opens one mock device (the first available, or the one ``info`` names)."""

    _registry: ClassVar[list[MockDevice]] = []  # replaced per mock module by make_depthai

    def __init__(self, info: DeviceInfo | str | None = None, *args: Any, **kwargs: Any) -> None:
        free = [d for d in self._registry if not d.opened]
        want = info.getDeviceId() if isinstance(info, DeviceInfo) else info
        match = [d for d in free if want in (None, "", d.device_id)]
        if not match:
            raise RuntimeError(f"No available devices (wanted {want!r})")
        self.state = match[0]
        self.state.opened = True
        self.closed = False

    @classmethod
    def getAllAvailableDevices(cls) -> list[DeviceInfo]:
        return [DeviceInfo(d) for d in cls._registry if not d.opened]

    def getDeviceId(self) -> str:
        return self.state.device_id

    def getConnectedCameras(self) -> list[Any]:
        return [getattr(CameraBoardSocket, s) for s in self.state.sensors]

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self.state.opened = False

    def isClosed(self) -> bool:
        return self.closed

    def __enter__(self) -> Device:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Pipeline:
    """``dai.Pipeline``: with no device given it opens the first available one, as depthai v3 does."""

    _device_class: type[Device] = Device

    def __init__(self, device: Device | bool | None = None) -> None:
        self._own = not isinstance(device, Device)
        self.device = device if isinstance(device, Device) else self._device_class()
        self.device_state = self.device.state
        self._running = False

    def create(self, node_class: type) -> Any:
        return node_class(self)

    def start(self) -> None:
        self._running = True

    def isRunning(self) -> bool:
        return self._running

    def stop(self) -> None:
        self._running = False

    def wait(self) -> None:
        self.stop()

    def getDefaultDevice(self) -> Device:
        return self.device

    def __enter__(self) -> Pipeline:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
        if self._own:
            self.device.close()


def make_depthai(devices: Sequence[MockDevice] | None = None) -> types.ModuleType:
    """A fresh module that stands in for ``depthai`` with these devices attached (default: one OAK-D with an
    IMX378 colour camera and an OV9281-like mono pair); add or remove devices through ``mod.devices``."""
    mod = types.ModuleType("depthai", "rollcam's mock of the depthai v3 device API (rollcam.host.testing)")
    registry = list(devices) if devices is not None else [MockDevice()]
    device_cls = type("Device", (Device,), {"_registry": registry})
    pipeline_cls = type("Pipeline", (Pipeline,), {"_device_class": device_cls})
    mod.__dict__.update(
        __version__=__version__, devices=registry, MockDevice=MockDevice, Device=device_cls, DeviceInfo=DeviceInfo,
        Pipeline=pipeline_cls, ImgFrame=ImgFrame, CameraControl=CameraControl, CameraBoardSocket=CameraBoardSocket,
        CameraExposureOffset=CameraExposureOffset,
        MessageQueue=MessageQueue, QueueClosed=QueueClosed, node=types.SimpleNamespace(Camera=_Camera),
    )
    return mod
