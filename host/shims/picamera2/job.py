"""``Job``: the result of a Picamera2 call made with ``wait=False`` or a ``signal_function``.

The call runs on its own thread; ``job.get_result(timeout)`` (or ``picam2.wait(job)``) returns its value or
re-raises its error, and ``signal_function(job)`` is called when it is done, as picamera2's jobs are.
"""

from __future__ import annotations

import concurrent.futures
import threading
from collections.abc import Callable
from typing import Any

CancelledError = concurrent.futures.CancelledError


class Job:
    """A call running in the background: ``get_result``, ``result``, ``done``, ``cancel``."""

    def __init__(self, call: Callable[[], Any], signal_function: Callable[[Job], None] | None = None,
                 jobs: set[Job] | None = None) -> None:
        self._future: concurrent.futures.Future[Any] = concurrent.futures.Future()
        self._signal = signal_function
        self._lock = threading.Lock()
        self._jobs = jobs
        if jobs is not None:
            jobs.add(self)
        self._thread = threading.Thread(target=self._run, args=(call,), name="picamera2-job", daemon=True)
        self._thread.start()

    def _run(self, call: Callable[[], Any]) -> None:
        if not self._future.set_running_or_notify_cancel():
            return
        try:
            value, error = call(), None
        except BaseException as exc:  # handed to whoever waits for the job
            value, error = None, exc
        with self._lock:
            cancelled = self._future.done()
            if not cancelled:
                if error is None:
                    self._future.set_result(value)
                else:
                    self._future.set_exception(error)
        if self._jobs is not None:
            self._jobs.discard(self)
        if cancelled:
            if hasattr(value, "release"):
                value.release()  # a request nobody will take
            return
        if self._signal is not None:
            self._signal(self)

    def cancel_running(self) -> None:
        """Fail the job with CancelledError now, even while it runs (picamera2's ``cancel_all_and_flush``);
        what its call returns later is dropped (a request is released)."""
        with self._lock:
            if not self._future.done():
                self._future.set_exception(CancelledError())
        if self._jobs is not None:
            self._jobs.discard(self)

    def done(self) -> bool:
        """True once the call has finished."""
        return self._future.done()

    def cancel(self) -> bool:
        """Cancel the job if it has not started."""
        return self._future.cancel()

    def get_result(self, timeout: float | None = None) -> Any:
        """The call's value (re-raises its error); TimeoutError after ``timeout`` seconds."""
        return self._future.result(timeout)

    result = get_result


def dispatch(call: Callable[[float | None], Any], wait: Any, signal_function: Callable[[Job], None] | None,
             jobs: set[Job] | None = None) -> Any:
    """Run ``call(timeout_s)`` as picamera2's ``wait`` says: None (wait unless a signal function is given),
    True (wait as long as it takes), False (return a Job), a number (wait that many seconds, then
    TimeoutError)."""
    if wait is None:
        wait = signal_function is None
    if wait is False:
        return Job(lambda: call(None), signal_function, jobs)
    timeout = None if wait is True else float(wait)
    if signal_function is None:
        return call(timeout)
    return Job(lambda: call(timeout), signal_function, jobs).get_result()
