"""rollcam's pytest plugin: fixtures that put emulated cameras and mocked device APIs under users' tests.

Installed with rollcam (a ``pytest11`` entry point), so any project's tests can use them without imports:

- ``rollcam_camera(sensor, scene=.., seed=.., **options)``: an open ``emu:`` source of any hw_config
  (name or YAML path) and scene, closed after the test.
- ``rollcam_v4l2_device(sensor, faults=.., **options)``: an emulated V4L2 device (``rollcam.emu.v4l2.Device``).
- ``rollcam_http_camera(sensor, faults=.., **options)``: the emulated camera's MJPEG server on 127.0.0.1.
- ``rollcam_mjpeg_server(frames)``: an MJPEG-over-HTTP server on 127.0.0.1 serving those Frames with
  rollcam's timing headers; its ``url`` opens as a source (``http://...``) or in ``cv2.VideoCapture``.
- ``rollcam_usb_backend(sensor, **scene)``: a pyusb backend on which ``usb.core.find`` finds emulated UVC
  cameras (the firmware camera behind a UVC 1.5 function).
- ``rollcam_serial_port(sensor, **scene)``: a pseudo-terminal that ``serial.Serial(port.path)`` opens, speaking
  the emulated firmware's control protocol.
- ``rollcam_picamera2(*sources)``: rollcam's stand-in ``picamera2`` (and ``libcamera``) importable for the
  test, on emulated cameras (sensor names or ``emu:`` URIs; default one imx219); cameras left open are closed
  and ``sys.path``/``sys.modules`` restored after it.
- ``mock_depthai``: a stand-in ``depthai`` module (``rollcam.host.testing.depthai_mock``) installed in
  ``sys.modules`` for the test, so an OAK capture script runs without hardware on emulated sensors.

Every factory that makes a device takes ``faults=``: a ``rollcam.common.faults`` plan or its text
(``"drop=5%,error=2%,seed=1"``), the same as ``rollcam emulate --faults`` and the ``emu:`` URI's ``faults=``;
the device's ``fault_stats`` counts what it injected (docs/faults.md).

Fixtures are lazy: importing this plugin loads nothing heavy, and a fixture's optional dependency is needed
only by the tests that use it.
"""

from __future__ import annotations

import sys
import urllib.parse
from collections.abc import Callable, Iterable, Iterator
from typing import Any

import pytest


@pytest.fixture
def rollcam_camera() -> Iterator[Callable[..., Any]]:
    """Factory of emulated cameras: ``rollcam_camera("imx219", scene="street", seed=3, size="640x360")``.

    Options are those of ``emu:`` URIs (see README); every camera opened is closed after the test.
    """
    from rollcam.host.sources import open_camera

    opened: list[Any] = []

    def make(sensor: str = "imx219", **options: Any) -> Any:
        if "faults" in options:  # a plan's text holds '%' and '=': sent quoted
            options["faults"] = urllib.parse.quote(str(options["faults"]), safe=",=@")
        query = "&".join(f"{k}={v}" for k, v in options.items())
        source = open_camera(f"emu:{sensor}" + (f"?{query}" if query else ""))
        opened.append(source)
        return source

    yield make
    for source in opened:
        source.close()


@pytest.fixture
def rollcam_mjpeg_server() -> Iterator[Callable[..., Any]]:
    """Factory of MJPEG test servers: ``server = rollcam_mjpeg_server(frames); open_camera(server.url)``."""
    from .mjpeg import MjpegTestServer

    servers: list[MjpegTestServer] = []

    def make(frames: Iterable[Any], **kwargs: Any) -> MjpegTestServer:
        server = MjpegTestServer(frames, **kwargs)
        servers.append(server)
        return server

    yield make
    for server in servers:
        server.close()


@pytest.fixture
def mock_depthai(monkeypatch: pytest.MonkeyPatch) -> Any:
    """A mock ``depthai`` module (one emulated OAK-D attached) in ``sys.modules`` for this test.

    ``import depthai as dai`` in the code under test then gets the mock; ``mock_depthai.devices`` lists the
    attached ``MockDevice`` objects (set ``frames=N`` to end the stream, ``scene``/``seed`` to pick what it
    sees, or append more devices; clear the list to test the no-device path).
    """
    from .depthai_mock import make_depthai

    mod = make_depthai()
    monkeypatch.setitem(sys.modules, "depthai", mod)
    return mod


_STANDINS = ("picamera2", "libcamera")


def _is_standin(module_name: str) -> bool:
    return any(module_name == n or module_name.startswith(n + ".") for n in _STANDINS)


@pytest.fixture
def rollcam_picamera2(monkeypatch: pytest.MonkeyPatch) -> Iterator[Callable[..., Any]]:
    """Factory that makes ``import picamera2`` find rollcam's stand-in for this test and returns the module:
    ``picamera2 = rollcam_picamera2("imx477", "emu:imx708?scene=flat")`` (camera N is the N-th source; none
    given: one imx219). Code under test imports it as usual. A real picamera2 already imported is put back
    afterwards."""
    from rollcam.host.servers.standins import PICAMERA2_ENV, shims_path

    saved = {k: sys.modules.pop(k) for k in [k for k in sys.modules if _is_standin(k)]}
    monkeypatch.syspath_prepend(str(shims_path()))

    def make(*sources: str) -> Any:
        if sources:
            monkeypatch.setenv(PICAMERA2_ENV, ";".join(sources))
        else:
            monkeypatch.delenv(PICAMERA2_ENV, raising=False)
        import picamera2

        return picamera2

    try:
        yield make
    finally:
        module = sys.modules.get("picamera2.picamera2")
        if module is not None and hasattr(module, "close_all"):
            module.close_all()
        for k in [k for k in sys.modules if _is_standin(k)]:
            del sys.modules[k]
        sys.modules.update(saved)


@pytest.fixture
def rollcam_usb_backend() -> Iterator[Callable[..., Any]]:
    """Factory of pyusb backends with emulated UVC cameras on them.

    ``backend = rollcam_usb_backend("imx219", scene="street", seed=1)`` returns a ``usb.backend.IBackend``;
    ``usb.core.find(idVendor=0x1209, idProduct=0x0001, backend=backend)`` then finds the camera and ordinary
    pyusb code negotiates (probe/commit) and streams from it. Each camera is a ``FirmwareCamera``; pass
    ``cameras=N`` for several on one bus (product ids 0x0001, 0x0002, ...). Streams stop after the test.
    """
    from rollcam.emu.uvc import DeviceIdentity, FirmwareProducer, UVCFunction
    from rollcam.emu.uvc.pyusb_backend import EmulatedBackend
    from rollcam.firmware.camera import FirmwareCamera

    functions: list[Any] = []

    def make(sensor: str = "imx219", *, cameras: int = 1, transfer: str = "iso", realtime: bool = False,
             faults: Any = None, size: Any = None, **scene: Any) -> Any:
        made = []
        for k in range(cameras):
            cam = FirmwareCamera(sensor, scene={"scene": "street", **scene}, serial_number=f"{k + 1:04d}",
                                 **({"size": size} if size is not None else {}))
            made.append(UVCFunction(FirmwareProducer(cam), transfer=transfer, realtime=realtime, faults=faults,
                                    identity=DeviceIdentity(product_id=DeviceIdentity.product_id + k,
                                                            serial=cam.serial_number)))
        functions.extend(made)
        return EmulatedBackend(made)

    yield make
    for f in functions:
        f.close()


@pytest.fixture
def rollcam_serial_port() -> Iterator[Callable[..., Any]]:
    """Factory of pseudo-terminal serial ports to an emulated camera's firmware (its control protocol).

    ``port = rollcam_serial_port("imx219")`` gives an object with ``path`` (open it with
    ``serial.Serial(port.path)``, as a real camera's port) and ``camera`` (the ``FirmwareCamera``); scene
    options go as keywords. Ports are closed and their ptys freed after the test.
    """
    from rollcam.emu.serial_pty import PtySerialServer
    from rollcam.firmware.camera import FirmwareCamera

    servers: list[Any] = []

    def make(sensor: str = "imx219", *, faults: Any = None, **scene: Any) -> Any:
        server = PtySerialServer(FirmwareCamera(sensor, scene={"scene": "street", **scene}), faults=faults)
        server.start()
        servers.append(server)
        return server

    yield make
    for server in servers:
        server.close()


@pytest.fixture
def rollcam_v4l2_device() -> Iterator[Callable[..., Any]]:
    """Factory of emulated V4L2 devices: ``dev = rollcam_v4l2_device("imx219", faults="drop=10%", size=(640,
    480), realtime=False)`` returns an open ``rollcam.emu.v4l2.Device`` (scene options as ``scene={...}``,
    camera options as keywords); devices are closed after the test."""
    from rollcam.emu.v4l2 import Device

    devices: list[Any] = []

    def make(sensor: str = "imx219", **options: Any) -> Any:
        options.setdefault("scene", {"scene": "street"})
        device = Device.open(sensor, **options)
        devices.append(device)
        return device

    yield make
    for device in devices:
        device.close()


@pytest.fixture
def rollcam_http_camera() -> Iterator[Callable[..., Any]]:
    """Factory of the emulated camera's MJPEG servers: ``srv = rollcam_http_camera("imx219", faults="cut=5%",
    size=(320, 240))`` returns a started ``rollcam.emu.http.mjpeg.MjpegServer`` on 127.0.0.1 (its ``url``
    opens in ``cv2.VideoCapture`` or as a source; ``fault_stats`` counts the injected faults)."""
    from rollcam.emu.http.mjpeg import MjpegServer
    from rollcam.firmware.camera import FirmwareCamera

    servers: list[Any] = []

    def make(sensor: str = "imx219", *, faults: Any = None, scene: Any = None, **options: Any) -> Any:
        camera = FirmwareCamera(sensor, scene=scene or {"scene": "street"}, **options)
        server = MjpegServer(camera, "127.0.0.1", 0, faults=faults)
        servers.append(server)
        server.start()
        return server

    yield make
    for server in servers:
        server.close()
