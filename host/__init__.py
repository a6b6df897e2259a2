"""Host side: camera sources, detectors, CLI. ``from rollcam.host import open_camera`` opens any source URI;
``VideoCapture`` is a drop-in for ``cv2.VideoCapture`` that also takes those URIs; ``shims_path()`` is the folder
of stand-in modules (``picamera2``) for unmodified programs, ``standin_env()`` a child's environment for them."""

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


def __getattr__(name: str) -> object:
    # open_camera imports numpy and VideoCapture OpenCV; load them on first use so ``import rollcam.host``
    # (and with it ``rollcam --help``) stays light.
    if name == "open_camera":
        from .sources import open_camera

        return open_camera
    if name == "VideoCapture":
        from .videocapture import VideoCapture

        return VideoCapture
    if name in ("shims_path", "standin_env"):
        from .servers import standins

        return getattr(standins, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["ConfigError", "DeviceError", "DeviceNotFoundError", "MissingDependencyError", "ProtocolError",
           "RollcamError", "SourceError", "VideoCapture", "open_camera", "shims_path", "standin_env"]
