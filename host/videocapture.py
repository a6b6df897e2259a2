"""``rollcam.host.VideoCapture``: a drop-in for ``cv2.VideoCapture`` that also opens rollcam source URIs.

``from rollcam.host import VideoCapture`` in place of ``cv2.VideoCapture`` is the only change an OpenCV
script needs to run on ``emu:``, ``file:``, ``oak:``, ``http://`` (MJPEG) and the other rollcam schemes.
Integers, paths and URLs of other schemes go to ``cv2.VideoCapture`` itself with OpenCV's own semantics, and
so does an ``http(s)://`` URL that is not an MJPEG stream rollcam can read.

For rollcam sources: ``read``/``grab``/``retrieve`` give 8-bit BGR (``CAP_PROP_CONVERT_RGB=0`` gives the
frame's own pixels), ``frame`` is the last rollcam ``Frame`` (timing and ground truth). ``get`` answers
FRAME_WIDTH/HEIGHT, FPS, POS_FRAMES, POS_MSEC (the frame's device timestamp), FRAME_COUNT (-1 when
endless), EXPOSURE (us), GAIN, CONVERT_RGB and FOURCC; other properties read 0, as OpenCV's backends
answer properties they lack. As OpenCV's FFmpeg backend reads a network stream's first frame when it opens
it, an ``http://`` stream is probed at open (its first frames are read ahead, and still returned by
``read``), so FRAME_WIDTH/HEIGHT and FPS are known before the first read (FPS from the parts' device
timestamps, else FFmpeg's 25). ``set`` changes FRAME_WIDTH/HEIGHT, FPS, EXPOSURE (us) and GAIN of an ``emu:``
stream (it continues at the same frame index with the new settings) and POS_FRAMES (seek) of ``emu:``;
on ``opencv:``/``v4l2:``/``oak:`` it goes to the device's controls. It returns False for what it cannot do.
"""

from __future__ import annotations

import os
from typing import Any
from urllib.parse import urlencode

import cv2
import numpy as np
from rollcam.common.errors import RollcamError

from .preview import frame_bgr
from .sources import SCHEMES, open_camera, parse_uri

EMU_SETTABLE = {cv2.CAP_PROP_FPS: "fps", cv2.CAP_PROP_EXPOSURE: "exposure_us", cv2.CAP_PROP_GAIN: "gain"}
CONTROL_NAMES = {cv2.CAP_PROP_FPS: "fps", cv2.CAP_PROP_EXPOSURE: "exposure", cv2.CAP_PROP_GAIN: "gain",
                 cv2.CAP_PROP_FRAME_WIDTH: "width", cv2.CAP_PROP_FRAME_HEIGHT: "height",
                 cv2.CAP_PROP_AUTO_EXPOSURE: "auto_exposure", cv2.CAP_PROP_BRIGHTNESS: "brightness"}
"""OpenCV property -> the ``set_control`` name of opencv:/v4l2: sources."""
OAK_CONTROLS = {cv2.CAP_PROP_EXPOSURE: "exposure_us", cv2.CAP_PROP_GAIN: "gain"}


def is_rollcam_uri(source: Any) -> bool:
    """True for a string naming a rollcam scheme (``emu:...``, ``oak:``, ``http://``...)."""
    if not isinstance(source, (str, os.PathLike)):
        return False
    text = os.fspath(source)
    scheme = text.split(":", 1)[0].lower() if ":" in text else ""
    return scheme in SCHEMES and len(scheme) > 1  # a drive letter (C:) is a path


class VideoCapture:
    """``cv2.VideoCapture``'s interface over rollcam sources (and plain OpenCV for everything else)."""

    def __init__(self, source: Any = None, apiPreference: int = cv2.CAP_ANY, *args: Any) -> None:
        self._cv: Any = None
        self._source: Any = None
        self._frame: Any = None
        self._grabbed = False
        self._convert = True
        self._uri: str | None = None
        self.error: RollcamError | None = None
        if source is not None:
            self.open(source, apiPreference, *args)

    # ------------------------------------------------------------------------------------------ open/close
    def open(self, source: Any, apiPreference: int = cv2.CAP_ANY, *args: Any) -> bool:
        """Open ``source`` (closing what was open); False when it cannot be opened (``error`` says why)."""
        self.release()
        if not is_rollcam_uri(source):
            self._cv = cv2.VideoCapture(source, apiPreference, *args)
            return bool(self._cv.isOpened())
        try:
            self._source = open_camera(os.fspath(source))
            self._uri = os.fspath(source)
            probe = getattr(self._source, "probe", None)
            if probe is not None:  # a stream that only its frames describe (OpenCV reads one at open, too)
                probe()
        except RollcamError as exc:
            if self._source is not None:
                self._source.close()
                self._source = None  # OpenCV reports failure by isOpened(), not by raising
            self.error = exc
            if parse_uri(os.fspath(source)).scheme in ("http", "https"):
                # Not an MJPEG stream rollcam can read (HLS, a plain video file...): OpenCV may still play it.
                self._cv = cv2.VideoCapture(os.fspath(source), apiPreference, *args)
                return bool(self._cv.isOpened())
            return False
        return True

    def isOpened(self) -> bool:
        """Whether a source is open."""
        if self._cv is not None:
            return bool(self._cv.isOpened())
        return self._source is not None

    def release(self) -> None:
        """Close the source; safe to call twice."""
        if self._cv is not None:
            self._cv.release()
            self._cv = None
        if self._source is not None:
            self._source.close()
            self._source = None
        self._frame, self._grabbed = None, False

    def __enter__(self) -> VideoCapture:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    # ------------------------------------------------------------------------------------------ frames
    @property
    def frame(self) -> Any:
        """The last grabbed rollcam Frame (timing, ground truth), or None."""
        return self._frame

    def grab(self) -> bool:
        """Take the next frame; False at the end of the stream or when nothing is open."""
        if self._cv is not None:
            return bool(self._cv.grab())
        if self._source is None:
            return False
        try:
            self._frame = self._source.read()
        except RollcamError as exc:
            self.error, self._frame = exc, None
        self._grabbed = self._frame is not None
        return self._grabbed

    def retrieve(self, image: np.ndarray | None = None, flag: int = 0) -> tuple[bool, np.ndarray | None]:
        """The grabbed frame as BGR (or raw when CONVERT_RGB is 0)."""
        if self._cv is not None:
            return self._cv.retrieve(image, flag) if image is not None else self._cv.retrieve()
        if not self._grabbed or self._frame is None:
            return False, None
        img = frame_bgr(self._frame) if self._convert else self._frame.data
        if image is not None and image.shape == img.shape and image.dtype == img.dtype:
            np.copyto(image, img)
            return True, image
        return True, img

    def read(self, image: np.ndarray | None = None) -> tuple[bool, np.ndarray | None]:
        """``grab()`` then ``retrieve()``."""
        if self._cv is not None:
            return self._cv.read(image) if image is not None else self._cv.read()
        if not self.grab():
            return False, None
        return self.retrieve(image)

    # ------------------------------------------------------------------------------------------ properties
    def get(self, propId: int) -> float:
        """A CAP_PROP_* value (0 for properties this source lacks)."""
        if self._cv is not None:
            return float(self._cv.get(propId))
        if self._source is None:
            return 0.0
        info = self._source.info()
        f = self._frame
        values: dict[int, Any] = {
            cv2.CAP_PROP_FRAME_WIDTH: f.width if f is not None else info.get("width"),
            cv2.CAP_PROP_FRAME_HEIGHT: f.height if f is not None else info.get("height"),
            cv2.CAP_PROP_FPS: info.get("fps"),
            cv2.CAP_PROP_POS_FRAMES: getattr(self._source, "index", None),
            cv2.CAP_PROP_POS_MSEC: f.timestamp_ns / 1e6 if f is not None else 0.0,
            cv2.CAP_PROP_FRAME_COUNT: getattr(self._source, "limit", None) or -1,
            cv2.CAP_PROP_EXPOSURE: (info["exposure_ns"] / 1000 if "exposure_ns" in info
                                    else (f.exposure_ns / 1000 if f is not None else None)),
            cv2.CAP_PROP_GAIN: parse_uri(self._uri).options.get("gain", 1.0) if self._uri else None,
            cv2.CAP_PROP_CONVERT_RGB: float(self._convert),
            cv2.CAP_PROP_FOURCC: _fourcc_code(f.format) if f is not None else None,
        }
        value = values.get(propId)
        try:
            return float(value) if value is not None else 0.0
        except (TypeError, ValueError):
            return 0.0

    def set(self, propId: int, value: float) -> bool:
        """Change a CAP_PROP_* value; False when the source cannot."""
        if self._cv is not None:
            return bool(self._cv.set(propId, value))
        if self._source is None:
            return False
        if propId == cv2.CAP_PROP_CONVERT_RGB:
            self._convert = bool(value)
            return True
        scheme = parse_uri(self._uri).scheme if self._uri else ""
        if scheme == "emu":
            return self._set_emu(propId, value)
        setter = getattr(self._source, "set_control", None)
        names = OAK_CONTROLS if scheme == "oak" else CONTROL_NAMES
        if setter is None or propId not in names:
            return False
        try:
            return bool(setter(names[propId], value))
        except RollcamError as exc:
            self.error = exc
            return False

    def _set_emu(self, propId: int, value: float) -> bool:
        parts = parse_uri(self._uri)
        index = self._source.index
        if propId == cv2.CAP_PROP_POS_FRAMES:
            if value < 0:
                return False
            self._source.index = int(value)
            return True
        opts = dict(parts.options)
        if propId in (cv2.CAP_PROP_FRAME_WIDTH, cv2.CAP_PROP_FRAME_HEIGHT):
            info = self._source.info()
            w, h = info["width"], info["height"]
            w, h = (int(value), h) if propId == cv2.CAP_PROP_FRAME_WIDTH else (w, int(value))
            opts["size"] = f"{w}x{h}"
        elif propId in EMU_SETTABLE:
            opts[EMU_SETTABLE[propId]] = repr(float(value))
        else:
            return False
        uri = f"emu:{parts.target}" + (f"?{urlencode(opts, safe='/:')}" if opts else "")
        try:
            new = open_camera(uri)
        except RollcamError as exc:
            self.error = exc
            return False
        self._source.close()
        self._source, self._uri = new, uri
        new.index = index
        return True

    def getBackendName(self) -> str:
        """``rollcam:SCHEME`` for rollcam sources, OpenCV's backend name otherwise."""
        if self._cv is not None:
            return str(self._cv.getBackendName())
        return f"rollcam:{parse_uri(self._uri).scheme}" if self._uri else ""


def _fourcc_code(fmt: str) -> int:
    return cv2.VideoWriter_fourcc(*fmt[:4].ljust(4))
