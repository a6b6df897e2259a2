"""``Process`` and ``Pool``: completed requests handed to other processes (picamera2's remote processing).

``Process(run, picam2, init)`` starts a child process that calls ``init()`` once and ``run(request, **kwargs)``
for each request sent to it with ``send(request)``, which returns a ``concurrent.futures.Future`` of the
value. ``Pool(run, count, picam2, init)`` spreads requests over ``count`` of them. The request a child gets
(``RemoteRequest``) has the frame's arrays, metadata and configuration, and the request's ``make_array``,
``make_buffer``, ``make_image``, ``save`` and ``save_dng``. A Pi shares the frame buffers themselves with the
child (dma-buf); here the child gets copies, so what it writes into ``RemoteMappedArray`` stays in the child.
"""

from __future__ import annotations

import collections
import multiprocessing as mp
import queue
import threading
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any

import numpy as np

from ._dng import write_dng
from ._helpers import Helpers
from .request import CompletedRequest, image_format, to_bgr

_CLOSE = "CLOSE"


class RemoteRequest:
    """A completed request as a child process gets it: its arrays (copies), metadata and configuration."""

    def __init__(self, request: CompletedRequest, **kwargs: Any) -> None:
        self._metadata = request.get_metadata()
        self.config = dict(request.config)
        self._arrays = {name: np.copy(array) for name, array in request.arrays.items()}
        self._kwargs = kwargs
        self._array_ref_count = 0

    def get_metadata(self) -> dict[str, Any]:
        """The frame's metadata."""
        return self._metadata

    def get_config(self) -> dict[str, Any]:
        """The camera configuration the frame was made with."""
        return self.config

    def make_array(self, stream_name: str) -> np.ndarray:
        """A copy of a stream's array."""
        return np.copy(self._arrays[stream_name])

    def make_buffer(self, stream_name: str) -> np.ndarray:
        """A copy of a stream's buffer as 1-D bytes."""
        return np.copy(self._arrays[stream_name]).reshape(-1).view(np.uint8)

    def make_image(self, stream_name: str) -> Any:
        """A PIL image of an RGB stream."""
        from PIL import Image

        config = self.config.get(stream_name)
        if config is None:
            raise RuntimeError(f"Stream {stream_name!r} is not defined")
        bgr = to_bgr(self._arrays[stream_name], config["format"])
        return Image.fromarray(np.ascontiguousarray(bgr[..., ::-1]))

    def save(self, file_output: Any, name: str = "main", format_str: str | None = None,
             exif_data: dict[str, Any] | None = None) -> None:
        """Save a stream as an image file (JPEG, PNG, ...)."""
        img = self.make_image(name)
        ext = image_format(file_output, format_str)
        img.save(file_output, format={"jpg": "jpeg"}.get(ext, ext))

    def save_dng(self, file_output: Any, name: str = "raw") -> None:
        """Save the raw stream as a DNG."""
        if name not in self._arrays:
            raise RuntimeError(f"Stream {name!r} is not defined")
        write_dng(self._arrays[name], self.config[name], self._metadata, file_output)


class RemoteMappedArray:
    """``with RemoteMappedArray(request, "main") as m: m.array`` in a child process (its copy of the array)."""

    def __init__(self, request: RemoteRequest, stream_name: str) -> None:
        self._request, self._stream_name = request, stream_name
        self.array: np.ndarray | None = None

    def __enter__(self) -> RemoteMappedArray:
        self._request._array_ref_count += 1
        self.array = self._request._arrays[self._stream_name]
        return self

    def __exit__(self, *exc: object) -> None:
        self._request._array_ref_count -= 1
        self.array = None


def _child(send: Any, back: Any, run: Callable[..., Any], init: Callable[[], None] | None) -> None:
    """The child process: ``init()``, then each request's ``run`` value (or its error) back, until CLOSE."""
    if init is not None:
        init()
    while (msg := send.get()) != _CLOSE:
        back.put(_outcome(run, msg))
    back.put(("closed", None))


def _outcome(run: Callable[..., Any], request: RemoteRequest) -> tuple[str, Any]:
    """``("ok", value)`` of ``run(request)``, or ``("error", exception)`` for the parent's Future."""
    try:
        return "ok", run(request, **request._kwargs)
    except Exception as exc:
        return "error", exc


class Process:
    """A child process that runs ``run(request)`` for each request sent; ``send`` returns a Future.
    A result not back within ``timeout`` seconds fails its Future with TimeoutError."""

    def __init__(self, run: Callable[..., Any], picam2: Any, init: Callable[[], None] | None = None,
                 timeout: float | None = 30) -> None:
        self._send, self._back = mp.Queue(), mp.Queue()
        self._sent: collections.deque[tuple[CompletedRequest, Future[Any]]] = collections.deque()
        self._timeout = timeout
        self._process = mp.Process(target=_child, args=(self._send, self._back, run, init), daemon=True)
        self._process.start()
        self.helpers = Helpers(picam2)
        self._thread = threading.Thread(target=self._results, name="picamera2-remote", daemon=True)
        self._thread.start()

    @property
    def _requests_sent(self) -> collections.deque[tuple[CompletedRequest, Future[Any]]]:
        return self._sent

    def _results(self) -> None:
        waited = 0.0
        while True:
            try:
                kind, value = self._back.get(timeout=1)
            except queue.Empty:
                waited = waited + 1 if self._sent else 0.0
                if self._timeout is not None and self._sent and waited >= self._timeout:
                    request, future = self._sent.popleft()
                    future.set_exception(TimeoutError("No result received for timeout period"))
                    request.release()
                    waited = 0.0
                if not self._process.is_alive() and not self._sent:
                    return
                continue
            waited = 0.0
            if kind == "closed":
                return
            request, future = self._sent.popleft()
            if kind == "ok":
                future.set_result(value)
            else:
                future.set_exception(value)
            request.release()

    def send(self, request: CompletedRequest, **kwargs: Any) -> Future[Any]:
        """Hand ``request`` to the child (it is held until the child is done with it); the Future of the
        value ``run`` returns."""
        future: Future[Any] = Future()
        request.acquire()
        remote = RemoteRequest(request, **kwargs)
        self._sent.append((request, future))
        self._send.put(remote)
        return future

    def close(self) -> None:
        """Finish the requests sent, then end the child."""
        self._send.put(_CLOSE)
        self._thread.join()
        self._process.join()


class Pool:
    """``count`` child processes; each request goes to the one with the fewest in hand."""

    def __init__(self, run: Callable[..., Any], count: int, picam2: Any, init: Callable[[], None] | None = None,
                 timeout: float | None = 30) -> None:
        self._processes = [Process(run, picam2, init, timeout) for _ in range(count)]
        self._next = 0

    def __enter__(self) -> Pool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def send(self, request: CompletedRequest, **kwargs: Any) -> Future[Any]:
        """Send ``request`` to the least busy process (round robin among equals)."""
        n = len(self._processes)
        index = min(range(n), key=lambda i: (len(self._processes[i]._sent), (i - self._next) % n))
        self._next = (self._next + 1) % n
        return self._processes[index].send(request, **kwargs)

    def close(self) -> None:
        """Close every process."""
        for process in self._processes:
            process.close()
