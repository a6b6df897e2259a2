"""Host side: camera sources, detectors, CLI. ``from rollcam.host import open_camera`` opens any source URI;
``VideoCapture`` is a drop-in for ``cv2.VideoCapture`` that also takes those URIs."""

from rollcam.common.errors import ConfigError, DeviceError, ProtocolError, RollcamError, SourceError

from .sources import open_camera


def __getattr__(name: str) -> object:
    # VideoCapture imports OpenCV; load it on first use so ``import rollcam.host`` stays light.
    if name == "VideoCapture":
        from .videocapture import VideoCapture

        return VideoCapture
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["ConfigError", "DeviceError", "ProtocolError", "RollcamError", "SourceError", "VideoCapture",
           "open_camera"]
