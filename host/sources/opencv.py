"""``opencv:N`` (camera index), ``opencv:PATH`` or ``opencv:URL`` -- anything ``cv2.VideoCapture`` opens.

Frames are BGR3 as OpenCV delivers them. Timestamps: a camera's buffer time when the backend reports one
(``CAP_PROP_POS_MSEC``: the V4L2 buffer timestamp, monotonic clock) or else the host's monotonic clock at
capture; a file's position in the video. Exposure: V4L2 cameras report theirs (exposure_time_absolute, in
100 us steps); other backends leave it 0. Sequence: the frame position for files, a counter for cameras.
Row timing comes from ``sensor=NAME`` (see ``rowtiming``). Options: ``sensor``, ``size`` (WxH request),
``fps``, ``exposure`` (the backend's own unit: 100 us steps with V4L2), ``auto_exposure`` (0/1), ``gain``,
``fourcc`` (e.g. MJPG), ``frames``. Controls can be changed later with ``set_control(name, value)``.
``v4l2:/dev/videoN`` is this source with OpenCV's V4L2 backend (see ``v4l2``).
"""

from __future__ import annotations

import contextlib
import sys
import time
from collections.abc import Callable, Iterator
from typing import Any

import cv2
import numpy as np
from rollcam.common.errors import DeviceError, DeviceNotFoundError, SourceError
from rollcam.sim.frame import Frame

from .base import CameraSource, SourceURI, finite_float, parse_size, positive_int
from .rowtiming import FrameTimer

OPTIONS = {"sensor", "size", "fps", "exposure", "auto_exposure", "gain", "fourcc", "frames"}
CONTROLS: dict[str, int] = {
    "width": cv2.CAP_PROP_FRAME_WIDTH,
    "height": cv2.CAP_PROP_FRAME_HEIGHT,
    "fps": cv2.CAP_PROP_FPS,
    "exposure": cv2.CAP_PROP_EXPOSURE,
    "auto_exposure": cv2.CAP_PROP_AUTO_EXPOSURE,
    "gain": cv2.CAP_PROP_GAIN,
    "brightness": cv2.CAP_PROP_BRIGHTNESS,
}
"""Control name -> OpenCV property; which ones a device honours depends on the device and backend."""

V4L2_EXPOSURE_UNIT_NS = 100_000
# V4L2's auto-exposure menu through OpenCV: 1 = manual, 3 = aperture priority (auto).
_AUTO_EXPOSURE = {0: 1, 1: 3}


@contextlib.contextmanager
def quiet_opencv() -> Iterator[None]:
    """OpenCV's own log silenced for a call (it prints ``[ WARN:0@...]`` lines on stderr when a camera or file
    cannot be opened); the level it had is restored afterwards."""
    logging = cv2.utils.logging
    level = logging.getLogLevel()
    logging.setLogLevel(logging.LOG_LEVEL_SILENT)
    try:
        yield
    finally:
        logging.setLogLevel(level)


def _fourcc(text: str) -> str:
    if len(text) != 4:
        raise ValueError("must be 4 characters, e.g. MJPG or YUYV")
    return text


class OpenCVSource(CameraSource):
    """Frames from ``cv2.VideoCapture`` (a camera, file or URL), with controls where the backend has them."""

    def __init__(self, uri: SourceURI, target: int | str, api: int = cv2.CAP_ANY, *,
                 clock: Callable[[], int] = time.monotonic_ns, hint: str = "") -> None:
        self.uri, self.target, self.clock = uri.uri, target, clock
        uri.take(set(), OPTIONS)
        self.limit = uri.get("frames", positive_int)
        self.timer = FrameTimer(uri.get("sensor", str), uri.uri)
        self.is_camera = isinstance(target, int) or str(target).startswith("/dev/")
        with quiet_opencv():  # a failed open logs WARN lines; the error below says it once, in rollcam's words
            self.cap = cv2.VideoCapture(target, api)
        # V4L2's exposure_time_absolute is in 100 us units; other backends use their own scales (or none).
        self._exposure_unit_ns = V4L2_EXPOSURE_UNIT_NS if self.is_camera and api == cv2.CAP_V4L2 else 0
        if not self.cap.isOpened():
            self.cap.release()
            # No camera at an index or node is a device that is not there; an unreadable file is bad input.
            error = DeviceNotFoundError if self.is_camera else SourceError
            raise error(f"source {uri.uri!r}: OpenCV cannot open {target!r}{hint}")
        self.index = 0
        try:
            self._apply_options(uri)
        except SourceError:
            self.cap.release()
            raise

    def _apply_options(self, uri: SourceURI) -> None:
        fourcc = uri.get("fourcc", _fourcc)
        if fourcc is not None:
            self.cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter_fourcc(*fourcc))
        size = uri.get("size", parse_size)
        if size is not None:
            self.set_control("width", size[0])
            self.set_control("height", size[1])
        auto = uri.get("auto_exposure", int)
        if auto is not None:
            if auto not in _AUTO_EXPOSURE:
                raise SourceError(f"source {uri.uri!r}: option auto_exposure={auto!r} must be 0 or 1")
            self.set_control("auto_exposure", _AUTO_EXPOSURE[auto])
        for name in ("fps", "exposure", "gain"):
            value = uri.get(name, finite_float)
            if value is not None:
                self.set_control(name, value)

    def set_control(self, name: str, value: float) -> bool:
        """Set a control (see CONTROLS); False when the device or backend refuses it."""
        if name not in CONTROLS:
            raise SourceError(f"source {self.uri!r}: unknown control {name!r}; known: {sorted(CONTROLS)}")
        return bool(self.cap.set(CONTROLS[name], float(value)))

    def controls(self) -> dict[str, float]:
        """Current value of every control the backend reports (unsupported ones read 0 or -1)."""
        return {name: float(self.cap.get(prop)) for name, prop in CONTROLS.items()}

    def read(self) -> Frame | None:
        """The next frame, or None at the end of a file (or after ``frames=N``)."""
        self._check_open()
        if self.limit is not None and self.index >= self.limit:
            return None
        pos = int(self.cap.get(cv2.CAP_PROP_POS_FRAMES)) if not self.is_camera else self.index
        ok, image = self.cap.read()
        host_ns = self.clock()
        if not ok or image is None:
            if self.is_camera:
                raise DeviceError(f"source {self.uri!r}: the camera delivered no frame (unplugged, or in use by "
                                  "another program?)")
            return None
        msec = float(self.cap.get(cv2.CAP_PROP_POS_MSEC))
        ts = round(msec * 1e6) if (msec > 0 or not self.is_camera) else host_ns
        exposure = 0
        if self._exposure_unit_ns:
            exposure = max(round(float(self.cap.get(cv2.CAP_PROP_EXPOSURE)) * self._exposure_unit_ns), 0)
        fmt = "GREY" if image.ndim == 2 else "BGR3"
        frame = self.timer.frame(np.asarray(image), fmt, pos, ts, exposure, meta={"host_ns": host_ns})
        self.index += 1
        return frame

    def _close(self) -> None:
        """Release the capture."""
        self.cap.release()

    def info(self) -> dict[str, Any]:
        """Target, backend, size, fps and row timing."""
        out: dict[str, Any] = {"uri": self.uri, "target": self.target, **self.timer.timing.to_json()}
        if not self.closed:
            out.update(backend=self.cap.getBackendName(), width=int(self.cap.get(cv2.CAP_PROP_FRAME_WIDTH)),
                       height=int(self.cap.get(cv2.CAP_PROP_FRAME_HEIGHT)), fps=float(self.cap.get(cv2.CAP_PROP_FPS)))
        return out


def camera_api() -> int:
    """OpenCV's native camera backend on this platform (V4L2 on Linux)."""
    return {"linux": cv2.CAP_V4L2, "win32": cv2.CAP_DSHOW, "darwin": cv2.CAP_AVFOUNDATION}.get(sys.platform,
                                                                                                 cv2.CAP_ANY)


def open_source(uri: SourceURI) -> OpenCVSource:
    """Scheme entry point for ``opencv:``: an integer is a camera index, anything else a path or URL."""
    if not uri.target:
        raise SourceError(f"source {uri.uri!r}: name a camera index, file or URL, e.g. opencv:0")
    if uri.target.isdigit():
        return OpenCVSource(uri, int(uri.target), camera_api(),
                            hint=" (no camera at that index: is one plugged in? 'rollcam list' shows video devices)")
    return OpenCVSource(uri, uri.target)
