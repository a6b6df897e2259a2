"""A depthai host node that emits emulated frames as ``dai.ImgFrame``: OAK pipelines on synthetic RS streams.

depthai v3 runs host-only pipelines without a device (``dai.Pipeline(False)``), so a pipeline written for
an OAK's camera can take its frames from any rollcam source instead::

    import depthai as dai
    from rollcam.host.oaknode import EmulatedCamera

    with dai.Pipeline(False) as pipeline:
        cam = pipeline.create(EmulatedCamera).build("emu:imx378?size=1280x720&scene=street", frames=100)
        queue = cam.out.createOutputQueue()
        pipeline.start()
        while pipeline.isRunning():
            img = queue.get().getCvFrame()          # BGR888i, device sequence and timestamp set

Each ImgFrame carries the source frame's sequence number, exposure time and device timestamp (depthai keeps
whole microseconds). As on an OAK, the timestamp is the end of exposure: ``getTimestampDevice()`` is the
frame's start of exposure plus its exposure, ``getTimestampDevice(dai.CameraExposureOffset.START)`` its start.
``cam.truth[sequence]`` holds the frame's ground-truth objects for synthetic sources (the newest
``TRUTH_KEPT`` frames, so an endless stream does not grow without bound). With
``realtime=True`` frames are paced at the source's frame period; otherwise they come as fast as they render.
After ``frames`` (or the end of a finite source) the node stops the pipeline, so ``isRunning()`` loops end.
``EmulatedCamera`` is built on first access, because depthai is an optional dependency (``rollcam[oak]``).
Import depthai before ``faster_coco_eval`` (used by ``rollcam eval``) in one process: the other order breaks
depthai's host-node subclassing, and ``EmulatedCamera`` then refuses with an error saying so.
"""

from __future__ import annotations

import datetime
import sys
import time
from typing import Any

from rollcam.common.errors import SourceError

from .sources.oak import import_depthai

_CLASS: dict[int, type] = {}
TRUTH_KEPT = 1024


def _make_class(dai: Any) -> type:
    class EmulatedCamera(dai.node.ThreadedHostNode):
        """Host node: a rollcam source's frames on output ``out`` as BGR888i ImgFrames."""

        def __init__(self) -> None:
            super().__init__()
            self.out = self.createOutput()
            self.uri = ""
            self.frames: int | None = None
            self.realtime = False
            self.truth: dict[int, Any] = {}
            self.error: BaseException | None = None

        def build(self, uri: str, frames: int | None = None, realtime: bool = False) -> EmulatedCamera:
            """Configure the source URI, the frame limit and pacing; returns the node (depthai's convention)."""
            from .sources import open_camera

            open_camera(uri).close()  # a bad URI fails here, in the caller's thread, not in the node's
            self.uri, self.frames, self.realtime = uri, frames, realtime
            return self

        def run(self) -> None:
            from .preview import frame_bgr
            from .sources import open_camera

            try:
                with open_camera(self.uri) as source:
                    t_first: int | None = None
                    wall_first = time.monotonic_ns()
                    n = 0
                    while self.isRunning() and (self.frames is None or n < self.frames):
                        frame = source.read()
                        if frame is None:
                            break
                        if self.realtime:
                            t_first = frame.timestamp_ns if t_first is None else t_first
                            wait_ns = (frame.timestamp_ns - t_first) - (time.monotonic_ns() - wall_first)
                            if wait_ns > 0:
                                time.sleep(wait_ns / 1e9)
                        msg = dai.ImgFrame()
                        msg.setCvFrame(frame_bgr(frame), dai.ImgFrame.Type.BGR888i)
                        msg.setSequenceNum(frame.sequence)
                        # depthai stamps an ImgFrame at the END of exposure (START = stamp - exposure), in
                        # whole us: store start + exposure so getTimestampDevice(START) is the frame's start.
                        exposure_us = frame.exposure_ns // 1000
                        settings = msg.cam
                        settings.exposureTimeUs = exposure_us
                        msg.cam = settings
                        stamp = datetime.timedelta(microseconds=frame.timestamp_ns // 1000 + exposure_us)
                        msg.setTimestampDevice(stamp)
                        msg.setTimestamp(stamp)
                        self.truth[frame.sequence] = frame.objects
                        if len(self.truth) > TRUTH_KEPT:
                            del self.truth[next(iter(self.truth))]  # dicts keep insertion order: the oldest
                        self.out.send(msg)
                        n += 1
            except BaseException as exc:  # surface it to the caller; the node's thread would swallow it
                self.error = exc
            finally:
                self.stopPipeline()

    return EmulatedCamera


def __getattr__(name: str) -> Any:
    if name == "EmulatedCamera":
        if "depthai" not in sys.modules and "faster_coco_eval" in sys.modules:
            # Both are pybind11 extensions; loaded in this order, depthai's Pipeline.create() silently makes
            # the base ThreadedHostNode instead of a Python subclass (seen with depthai 3.12, faster-coco-eval 1.8).
            raise SourceError("EmulatedCamera needs depthai imported before faster_coco_eval in this process "
                              "(a pybind11 clash between the two); import depthai first")
        dai = import_depthai()
        if id(dai) not in _CLASS:
            _CLASS[id(dai)] = _make_class(dai)
        return _CLASS[id(dai)]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
