"""Captures: the part of ``Picamera2`` that hands frames to the application.

Every capture takes the next completed request (with ``queue``, the newest one already waiting), as
picamera2's do, and each takes ``wait`` and ``signal_function`` with picamera2's meaning (``job.dispatch``).
A capture on a camera that is not started waits for ``start()`` (a thread that captures may be started
before the camera is), as picamera2's does.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Iterator
from typing import Any

from rollcam.common.lifecycle import Deadline

from .job import Job, dispatch
from .request import CompletedRequest


class CaptureMixin:
    """``capture_request``, ``capture_array(s)``, ``capture_buffer(s)``, ``capture_metadata``,
    ``capture_image``, ``capture_file``, ``drop_frames``, ``switch_mode*``, ``wait``."""

    _queue: Any
    _state: threading.Condition  # notified when the camera starts, stops or closes
    _jobs: set[Job]  # jobs in flight (cancel_all_and_flush)
    started: bool
    is_open: bool

    def _take(self, timeout_s: float | None, flush: Any = None) -> CompletedRequest:
        deadline = Deadline(timeout_s)
        queue = self._running_queue(deadline)
        accept = None
        if flush:
            after = time.monotonic_ns() if flush is True else int(flush)
            # picamera2's test: the frame started exposing (SensorTimestamp less ExposureTime) at or after it.
            accept = lambda r: r.metadata["SensorTimestamp"] - 1000 * r.metadata["ExposureTime"] >= after  # noqa: E731
        return queue.take(deadline.remaining(), accept=accept)

    def _running_queue(self, deadline: Deadline) -> Any:
        """The started camera's request queue, waiting for ``start()`` as picamera2's captures do."""
        with self._state:
            while not (self.started and self._queue is not None):
                if not self.is_open:
                    raise RuntimeError("Camera is closed")
                if deadline.expired:
                    raise TimeoutError("the camera was not started in time")
                self._state.wait(deadline.remaining())
            return self._queue

    def _with_request(self, use: Any, wait: Any, signal_function: Any) -> Any:
        def call(timeout_s: float | None) -> Any:
            req = self._take(timeout_s)
            try:
                return use(req)
            finally:
                req.release()
        return self._dispatch(call, wait, signal_function)

    def _dispatch(self, call: Any, wait: Any, signal_function: Any) -> Any:
        return dispatch(call, wait, signal_function, self._jobs)

    def cancel_all_and_flush(self) -> None:
        """Fail every job in flight with CancelledError and release the requests waiting to be captured."""
        for job in list(self._jobs):
            job.cancel_running()
        if self._queue is not None:
            self._queue.flush()

    def wait(self, job: Job, timeout: float | None = None) -> Any:
        """The result of a job from a call made with ``wait=False``."""
        return job.get_result(timeout)

    def capture_request(self, wait: Any = None, signal_function: Any = None, flush: Any = None) -> Any:
        """The next completed request; the caller must ``release()`` it (``flush``: one that started exposing
        after now (True) or after a time.monotonic_ns() value)."""
        return self._dispatch(lambda t: self._take(t, flush), wait, signal_function)

    @contextlib.contextmanager
    def captured_request(self, wait: Any = None, flush: Any = None) -> Iterator[CompletedRequest]:
        """``with picam2.captured_request() as request:`` (released at the end of the block)."""
        req = self.capture_request(wait=wait, flush=flush)
        try:
            yield req
        finally:
            req.release()

    def capture_metadata(self, wait: Any = None, signal_function: Any = None) -> Any:
        """The next frame's metadata."""
        return self._with_request(lambda r: r.get_metadata(), wait, signal_function)

    def capture_array(self, name: str = "main", wait: Any = None, signal_function: Any = None) -> Any:
        """The next frame's image of stream ``name`` as an array."""
        return self._with_request(lambda r: r.make_array(name), wait, signal_function)

    def capture_arrays(self, names: list[str] | None = None, wait: Any = None, signal_function: Any = None) -> Any:
        """Arrays of several streams of one frame, and its metadata: ``(arrays, metadata)``."""
        names = names or ["main"]
        return self._with_request(lambda r: ([r.make_array(n) for n in names], r.get_metadata()), wait,
                                  signal_function)

    def capture_buffer(self, name: str = "main", wait: Any = None, signal_function: Any = None) -> Any:
        """The next frame's buffer of stream ``name`` as 1-D bytes."""
        return self._with_request(lambda r: r.make_buffer(name), wait, signal_function)

    def capture_buffers(self, names: list[str] | None = None, wait: Any = None, signal_function: Any = None) -> Any:
        """Buffers of several streams of one frame, and its metadata."""
        names = names or ["main"]
        return self._with_request(lambda r: ([r.make_buffer(n) for n in names], r.get_metadata()), wait,
                                  signal_function)

    def capture_image(self, name: str = "main", wait: Any = None, signal_function: Any = None) -> Any:
        """The next frame's image of stream ``name`` as a PIL image."""
        return self._with_request(lambda r: r.make_image(name), wait, signal_function)

    def capture_file(self, file_output: Any, name: str = "main", format: str | None = None,
                     wait: Any = None, signal_function: Any = None, exif_data: Any = None) -> Any:
        """Save the next frame's stream ``name`` (JPEG, PNG, ...) to a path or file object; returns its
        metadata."""
        def use(r: CompletedRequest) -> dict[str, Any]:
            r.save(name, file_output, format=format, exif_data=exif_data)
            return r.get_metadata()
        return self._with_request(use, wait, signal_function)

    def drop_frames(self, num_frames: int, wait: Any = None, signal_function: Any = None) -> Any:
        """Discard the next ``num_frames`` frames."""
        def call(timeout_s: float | None) -> None:
            for _ in range(int(num_frames)):
                self._take(timeout_s).release()
        return self._dispatch(call, wait, signal_function)

    def switch_mode(self, camera_config: Any, wait: Any = None, signal_function: Any = None) -> Any:
        """Stop, configure with ``camera_config`` and start again; returns the configuration in effect."""
        def call(_: float | None) -> dict[str, Any]:
            self.stop()
            self.configure(camera_config)
            self.start()
            return self.camera_config
        return self._dispatch(call, wait, signal_function)

    def _switch_and(self, camera_config: Any, use: Any, wait: Any, signal_function: Any, delay: int = 0,
                    then: str = "back") -> Any:
        """Switch to ``camera_config``, drop ``delay`` frames, ``use`` the next request, then switch back
        (``then="back"``), stop (``"stop"``) or stay (``"stay"``)."""
        def call(timeout_s: float | None) -> Any:
            previous = self.camera_config
            self.switch_mode(camera_config)
            try:
                for _ in range(int(delay)):
                    self._take(timeout_s).release()
                req = self._take(timeout_s)
                try:
                    return use(req)
                finally:
                    req.release()
            finally:
                if then == "stop":
                    self.stop()
                elif then == "back" and previous:
                    self.switch_mode(previous)
        return self._dispatch(call, wait, signal_function)

    def switch_mode_and_capture_array(self, camera_config: Any, name: str = "main", wait: Any = None,
                                      signal_function: Any = None, delay: int = 0) -> Any:
        """Switch mode, capture an array of stream ``name``, switch back."""
        return self._switch_and(camera_config, lambda r: r.make_array(name), wait, signal_function, delay)

    def switch_mode_and_capture_buffers(self, camera_config: Any, names: list[str] | None = None,
                                        wait: Any = None, signal_function: Any = None, delay: int = 0) -> Any:
        """Switch mode, capture the buffers of ``names`` (default main) and the metadata, switch back."""
        names = names or ["main"]
        return self._switch_and(camera_config, lambda r: ([r.make_buffer(n) for n in names], r.get_metadata()),
                                wait, signal_function, delay)

    def switch_mode_and_capture_image(self, camera_config: Any, name: str = "main", wait: Any = None,
                                      signal_function: Any = None, delay: int = 0) -> Any:
        """Switch mode, capture stream ``name`` as a PIL image, switch back."""
        return self._switch_and(camera_config, lambda r: r.make_image(name), wait, signal_function, delay)

    def switch_mode_and_capture_file(self, camera_config: Any, file_output: Any, name: str = "main",
                                     format: str | None = None, wait: Any = None,
                                     signal_function: Any = None, delay: int = 0, exif_data: Any = None) -> Any:
        """Switch mode, save stream ``name`` to a file, switch back; returns the frame's metadata."""
        def use(r: CompletedRequest) -> dict[str, Any]:
            r.save(name, file_output, format=format, exif_data=exif_data)
            return r.get_metadata()
        return self._switch_and(camera_config, use, wait, signal_function, delay)

    def switch_mode_and_capture_request(self, camera_config: Any, wait: Any = None, signal_function: Any = None,
                                        delay: int = 0) -> Any:
        """Switch mode and capture a request (its arrays stay valid after the switch back)."""
        return self._switch_and(camera_config, _keep, wait, signal_function, delay)

    def switch_mode_capture_request_and_stop(self, camera_config: Any, wait: Any = None,
                                             signal_function: Any = None) -> Any:
        """Switch mode, capture a request and stop the camera (the request stays valid until released)."""
        return self._switch_and(camera_config, _keep, wait, signal_function, then="stop")

    def autofocus_cycle(self, wait: Any = None, signal_function: Any = None) -> Any:
        """Run one autofocus scan (AfMode Auto, AfTrigger Start) and wait for its end: True when Focused."""
        self.set_controls({"AfMode": 1, "AfTrigger": 0})

        def call(timeout_s: float | None) -> bool:
            deadline = Deadline(timeout_s)
            while True:
                req = self._take(deadline.remaining())
                try:
                    md = req.get_metadata()
                finally:
                    req.release()
                if md.get("AfMode") == 1 and md.get("AfState") in (2, 3):
                    return md["AfState"] == 2
        return self._dispatch(call, wait, signal_function)

    def start_and_capture_file(self, name: str = "image.jpg", delay: float = 1, preview_mode: Any = "preview",
                               capture_mode: Any = "still", show_preview: bool = False,
                               exif_data: Any = None) -> None:
        """Start in ``preview_mode``, wait ``delay`` seconds, save a still in ``capture_mode``, stop."""
        self.start_and_capture_files(name, delay, preview_mode, capture_mode, 1, 0, show_preview, exif_data)

    def start_and_capture_files(self, name: str = "image{:03d}.jpg", initial_delay: float = 1,
                                preview_mode: Any = "preview", capture_mode: Any = "still", num_files: int = 1,
                                delay: float = 1, show_preview: bool = False, exif_data: Any = None) -> None:
        """Start in ``preview_mode``, wait ``initial_delay`` s, then save ``num_files`` stills in
        ``capture_mode`` (``name`` formatted with the count), ``delay`` s apart, and stop. With a delay the
        camera goes back to the preview mode between stills; without one it stays in the still mode."""
        if self.started:
            self.stop()
        self.configure(preview_mode)
        self.start(show_preview=show_preview)
        time.sleep(initial_delay)
        for i in range(int(num_files)):
            if i and delay:
                time.sleep(delay)
            self._switch_and(capture_mode, lambda r, i=i: r.save("main", name.format(i), exif_data=exif_data),
                             True, None, then="back" if delay else "stay")
        self.stop()


def _keep(request: CompletedRequest) -> CompletedRequest:
    """Take a reference, so that the request outlives the capture that made it."""
    request.acquire()
    return request
