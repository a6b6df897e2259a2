"""Host side: camera sources, detectors, CLI. ``from rollcam.host import open_camera`` opens any source URI;
``VideoCapture`` is a drop-in for ``cv2.VideoCapture`` that also takes those URIs; ``shims_path()`` is the folder
of stand-in modules (``picamera2``) for unmodified programs, ``standin_env()`` a child's environment for them;
``run_program``, ``serving``, ``program_environment`` (``rollcam run``), ``serve`` (``rollcam emulate``),
``read_capture`` and ``EmulatedCamera`` (the depthai node) are the other entry points (``PUBLIC``)."""

import importlib

from rollcam.common.errors import (
    ConfigError,
    DeviceError,
    DeviceNotFoundError,
    MissingDependencyError,
    ProtocolError,
    RollcamError,
    SourceError,
)
from rollcam.firmware.insensor import set_network_loader as _set_network_loader

# The emulated camera's in-sensor networks are host detectors: registered by name, imported on first use.
_set_network_loader("rollcam.host.detectors.onchip:load_network", replace=False)


PUBLIC = {
    "open_camera": "sources",
    "VideoCapture": "videocapture",
    "shims_path": "servers.standins",
    "standin_env": "servers.standins",
    "run_program": "servers.devnodes",
    "serving": "servers.devnodes",
    "program_environment": "servers.devnodes",
    "serve": "servers.emulate",
    "read_capture": "recording.capture",
    "EmulatedCamera": "integrations.oaknode",
}
"""Public names of ``rollcam.host`` -> the module under it that defines each: the documented import path of every
entry point whatever folder its module lives in (docs/api.md)."""


def __getattr__(name: str) -> object:
    # The entry points import numpy, OpenCV or depthai; load each on first use so ``import rollcam.host`` (and
    # with it ``rollcam --help``) stays light.
    if name in PUBLIC:
        return getattr(importlib.import_module(f"{__name__}.{PUBLIC[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["ConfigError", "DeviceError", "DeviceNotFoundError", "EmulatedCamera", "MissingDependencyError",
           "ProtocolError", "RollcamError", "SourceError", "VideoCapture", "open_camera", "program_environment",
           "read_capture", "run_program", "serve", "serving", "shims_path", "standin_env"]
