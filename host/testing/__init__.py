"""rollcam's pytest plugin: fixtures that put emulated cameras and mocked device APIs under users' tests.

Installed with rollcam (a ``pytest11`` entry point), so any project's tests can use them without imports:

- ``rollcam_camera(sensor, scene=.., seed=.., **options)``: an open ``emu:`` source of any hw_config
  (name or YAML path) and scene, closed after the test.
- ``rollcam_mjpeg_server(frames)``: an MJPEG-over-HTTP server on 127.0.0.1 serving those Frames with
  rollcam's timing headers; its ``url`` opens as a source (``http://...``) or in ``cv2.VideoCapture``.
- ``mock_depthai``: a stand-in ``depthai`` module (``rollcam.host.testing.depthai_mock``) installed in
  ``sys.modules`` for the test, so an OAK capture script runs without hardware on emulated sensors.

Fixtures are lazy: importing this plugin loads nothing heavy, and a fixture's optional dependency is needed
only by the tests that use it.
"""

from __future__ import annotations

import sys
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


# ---- Fixtures of the emulated device transports go here (kept with their emulators' code):
#   rollcam_usb_backend : a pyusb backend that enumerates emulated UVC cameras (emu's pyusb backend)
#   rollcam_serial_port : a pty serial port connected to the emulated firmware's control protocol
