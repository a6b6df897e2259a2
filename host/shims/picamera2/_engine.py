"""The running camera: a thread that makes each frame at its time and hands it over as a completed request.

Each turn: the controls set since the last frame are applied together (one frame boundary), the device plans
its next frame (late ones are skipped, as a sensor's frames go on whether or not anyone reads them), the
thread waits until that frame's last line is read out (real time, device clock), renders it and makes every
stream's array. The frame is dropped when the application holds all ``buffer_count`` buffers. Completed
requests wait in a short queue: with ``queue`` (and more than one buffer) the newest one is kept so a capture
returns at once, as picamera2's is; otherwise a capture waits for the next frame.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from rollcam.common.lifecycle import Deadline, Worker

from .request import CompletedRequest

_log = logging.getLogger("picamera2")


class RequestQueue:
    """Completed requests waiting for the application, and the count of buffers it holds."""

    def __init__(self, buffer_count: int, keep: int) -> None:
        self.buffer_count, self.keep = buffer_count, keep
        self.cond = threading.Condition(threading.RLock())  # reentrant: a release under it returns a buffer
        self.waiting = collections.deque[CompletedRequest]()
        self.held = 0  # requests completed and not yet released: queued here or with the application
        self.readers = 0
        self.running = True
        self.dropped = 0
        self.failure: BaseException | None = None  # what ended the camera's thread, if it failed

    def has_buffer(self) -> bool:
        """True when a buffer is free for the next frame."""
        with self.cond:
            return self.held < self.buffer_count

    def push(self, req: CompletedRequest) -> None:
        """A new completed request; the oldest queued ones beyond what readers and ``keep`` need are released."""
        with self.cond:
            self.held += 1
            self.waiting.append(req)
            surplus = []
            while len(self.waiting) > max(self.keep, self.readers):
                surplus.append(self.waiting.popleft())
            self.cond.notify_all()
        for old in surplus:
            old.release()

    def returned(self) -> None:
        """A request's last reference was released: its buffer is free again."""
        with self.cond:
            self.held -= 1

    def take(self, timeout_s: float | None, fresh: bool = False,
             accept: Callable[[CompletedRequest], bool] | None = None) -> CompletedRequest:
        """The oldest waiting request (``fresh``: one completed after this call); ``accept`` refuses stale
        ones, released at once so that their buffers take new frames (picamera2's flush does the same).
        TimeoutError after ``timeout_s``; RuntimeError when the camera stops."""
        deadline = Deadline(None if timeout_s is None else max(timeout_s, 0.0))  # None: wait for ever
        discard: list[CompletedRequest] = []
        try:
            with self.cond:
                if fresh:
                    discard.extend(self.waiting)
                    self.waiting.clear()
                self.readers += 1
                try:
                    while True:
                        while self.waiting:
                            req = self.waiting.popleft()
                            if accept is None or accept(req):
                                return req
                            req.release()  # the lock is reentrant: its buffer comes back now
                        if not self.running:
                            if self.failure is not None:
                                raise RuntimeError(f"the camera failed: {self.failure!r}") from self.failure
                            raise RuntimeError("Camera is not running (start() it before capturing)")
                        if deadline.expired:
                            raise TimeoutError("no frame arrived in time")
                        self.cond.wait(deadline.remaining())
                finally:
                    self.readers -= 1
        finally:
            _release_all(discard)  # outside the lock: a release returns its buffer under it

    def flush(self) -> None:
        """Release the requests waiting to be captured."""
        with self.cond:
            out = list(self.waiting)
            self.waiting.clear()
        _release_all(out)

    def stop(self) -> list[CompletedRequest]:
        """Stop: waiting readers fail, queued requests are returned for release."""
        with self.cond:
            self.running = False
            out = list(self.waiting)
            self.waiting.clear()
            self.cond.notify_all()
        return out


def _release_all(reqs: list[CompletedRequest]) -> None:
    for r in reqs:
        r.release()


class Engine:
    """Frames of a started camera: the thread, its queue, and the per-frame hooks."""

    def __init__(self, camera: Any, queue: RequestQueue, take_controls: Callable[[], dict[str, Any]],
                 make_request: Callable[[Any, Any], CompletedRequest | None]) -> None:
        self.camera, self.queue = camera, queue
        self.take_controls, self.make_request = take_controls, make_request
        self.worker = Worker(self._run, name=f"picamera2-{camera.num}")

    def start(self) -> None:
        """Stream on and start the thread (compiles the renderer first on a cold cache)."""
        self.camera.device.stream_on()
        self.worker.start()

    def stop(self) -> None:
        """Stop the thread and the stream; queued requests are released; re-raises a thread failure."""
        self.worker.stop()
        try:
            self.worker.close()
        finally:
            self.camera.device.stream_off()
            _release_all(self.queue.stop())

    def _run(self) -> None:
        dev, stop = self.camera.device, self.worker.stop_event
        try:
            while not stop.is_set():
                changes = self.take_controls()
                if changes:
                    try:
                        self.camera.apply(changes)
                    except (ValueError, RuntimeError) as exc:  # as libcamera does: the frames go on
                        _log.error("controls %r not applied: %s", changes, exc)
                plan = dev.plan_next(dev.clock_ns())
                if plan is None:
                    dev.wait_changed(0.05)
                    continue
                wait_s = (dev.host_ns(plan.due_ns) - time.monotonic_ns()) / 1e9
                if wait_s > 0 and stop.wait(wait_s):
                    break
                if not self.queue.has_buffer():
                    self.queue.dropped += 1
                    continue
                req = self.make_request(plan, dev.render(plan))
                if req is not None:
                    self.queue.push(req)
        except BaseException as exc:
            self.queue.failure = exc
            raise
        finally:
            _release_all(self.queue.stop())
