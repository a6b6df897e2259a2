"""A depthai host node that emits emulated frames as ``dai.ImgFrame``: OAK pipelines on synthetic RS streams.

depthai v3 runs host-only pipelines without a device (``dai.Pipeline(False)``), so a pipeline written for
an OAK's camera can take its frames from any rollcam source instead::

    import depthai as dai
    from rollcam.host.integrations.oaknode import EmulatedCamera

    with dai.Pipeline(False) as pipeline:
        cam = pipeline.create(EmulatedCamera).build("emu:imx378?size=640x360&scene=street", frames=10)
        queue = cam.out.createOutputQueue()
        pipeline.start()
        images = []
        while pipeline.isRunning():
            frame = queue.get()                     # a dai.ImgFrame: BGR888i, device sequence and timestamp
            images.append(frame.getCvFrame())       # all 10, then the loop ends

(tests/test_oaknode.py runs this example as written.)

Each ImgFrame carries the source frame's sequence number, exposure time and device timestamp (depthai keeps
whole microseconds). As on an OAK, the timestamp is the end of exposure: ``getTimestampDevice()`` is the
frame's start of exposure plus its exposure, ``getTimestampDevice(dai.CameraExposureOffset.START)`` its start.
``cam.truth[sequence]`` holds the frame's ground-truth objects for synthetic sources (the newest
``TRUTH_KEPT`` frames, so an endless stream does not grow without bound). With
``realtime=True`` frames are paced at the source's frame period; otherwise they come as fast as they render.
After ``frames`` (or the end of a finite source) the pipeline stops, so ``isRunning()`` loops end: a queue made
by ``cam.out.createOutputQueue()`` stops it as it hands out the last frame (so the loop above gets every frame
and then ends, where depthai's own ReplayVideo makes ``get`` raise ``MessageQueue was closed``); a node fed
only through ``cam.out.link(...)`` stops it after sending the last frame. If the node fails, the queue's
``get`` raises its error as SourceError (also kept in ``cam.error``).
``EmulatedCamera`` is built on first access, so importing this module does not load depthai.
Import depthai before ``faster_coco_eval`` (used by ``rollcam eval``) in one process: the other order breaks
depthai's host-node subclassing, and ``EmulatedCamera`` then refuses with an error saying so.
"""

from __future__ import annotations

import datetime
import sys
import threading
import time
from typing import Any

from rollcam.common.errors import SourceError

from ..sources.oak import import_depthai

_CLASS: dict[int, type] = {}
TRUTH_KEPT = 1024


def _make_class(dai: Any) -> type:
    queue_closed = dai.MessageQueue.QueueException

    class OutputQueue:
        """depthai's MessageQueue for ``cam.out``, except that taking the stream's last frame stops the
        pipeline before the frame is returned: ``while pipeline.isRunning(): queue.get()`` then ends after the
        last frame instead of blocking in ``get`` until depthai closes the queue (``MessageQueue was closed``).
        A node that failed re-raises its error (as SourceError) where depthai would say the queue closed."""

        def __init__(self, queue: Any, node: Any) -> None:
            self._queue, self._node = queue, node

        def __getattr__(self, name: str) -> Any:
            return getattr(self._queue, name)

        def _call(self, method: str, *args: Any, **kwargs: Any) -> Any:
            try:
                got = getattr(self._queue, method)(*args, **kwargs)
            except queue_closed:
                self._node.check()
                raise
            for msg in got if isinstance(got, list) else [got]:
                if msg is not None:
                    self._node.message_taken(msg)
            return got

        def get(self, *args: Any, **kwargs: Any) -> Any:
            return self._call("get", *args, **kwargs)

        def tryGet(self) -> Any:
            return self._call("tryGet")

        def getAll(self, *args: Any, **kwargs: Any) -> Any:
            return self._call("getAll", *args, **kwargs)

        def tryGetAll(self) -> Any:
            return self._call("tryGetAll")

    class Output:
        """The node's depthai output (``link`` and the rest pass through); its queues are ``OutputQueue``s."""

        def __init__(self, output: Any, node: Any) -> None:
            self.output, self._node = output, node

        def __getattr__(self, name: str) -> Any:
            return getattr(self.output, name)

        def createOutputQueue(self, *args: Any, **kwargs: Any) -> OutputQueue:
            self._node.queue_opened()
            return OutputQueue(self.output.createOutputQueue(*args, **kwargs), self._node)

    class EmulatedCamera(dai.node.ThreadedHostNode):
        """Host node: a rollcam source's frames on output ``out`` as BGR888i ImgFrames."""

        def __init__(self) -> None:
            super().__init__()
            self.out = Output(self.createOutput(), self)
            self.uri = ""
            self.frames: int | None = None
            self.realtime = False
            self.truth: dict[int, Any] = {}
            self.error: BaseException | None = None  # what ended run() early; check() raises it
            self._queues = 0
            self._last_seq: int | None = None  # sequence number of the stream's last frame, once it is sent
            self._last_taken = threading.Event()

        def build(self, uri: str, frames: int | None = None, realtime: bool = False) -> EmulatedCamera:
            """Configure the source URI, the frame limit and pacing; returns the node (depthai's convention)."""
            from ..sources import open_camera

            open_camera(uri).close()  # a bad URI fails here, in the caller's thread, not in the node's
            self.uri, self.frames, self.realtime = uri, frames, realtime
            return self

        def check(self) -> None:
            """Raise what stopped the node's thread (as SourceError), if anything did."""
            if self.error is not None:
                raise SourceError(f"EmulatedCamera({self.uri!r}) failed: {self.error!r}") from self.error

        def queue_opened(self) -> None:
            """A consumer opened a queue on ``out``: the last frame now waits until one takes it."""
            self._queues += 1

        def message_taken(self, msg: Any) -> None:
            """A consumer took ``msg``: once it is the last frame, the pipeline stops (before it is returned)."""
            if self._last_seq is not None and msg.getSequenceNum() == self._last_seq and \
                    not self._last_taken.is_set():
                self._last_taken.set()
                self.getParentPipeline().stop()

        def run(self) -> None:
            try:
                self._stream()
                # The last frame is out: with queues, the consumer that takes it stops the pipeline (see
                # OutputQueue); stopping here could close the queue before the frame is taken.
                while self._queues and self.isRunning() and not self._last_taken.wait(0.05):
                    pass
            except BaseException as exc:  # surfaced by the queues (check()); depthai's thread would swallow it
                self.error = exc
            finally:
                if not self._last_taken.is_set():
                    self.stopPipeline()

        def _stream(self) -> None:
            from ..preview import frame_bgr
            from ..sources import open_camera

            with open_camera(self.uri) as source:
                t_first: int | None = None
                wall_first = time.monotonic_ns()
                n = 0
                frame = source.read() if self.frames != 0 else None
                while frame is not None and self.isRunning():
                    n += 1
                    # Read one ahead: the last frame must be known as the last before it is sent.
                    following = None if self.frames is not None and n >= self.frames else source.read()
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
                    if following is None:
                        self._last_seq = frame.sequence
                    self.out.output.send(msg)
                    frame = following

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
