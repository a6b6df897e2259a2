"""Where dataset tasks run: in process, on a local process pool, or on a Dask cluster.

Each executor takes a picklable function of one ``Task`` and yields its results as tasks finish (any order:
the driver commits samples one by one and the final files are built from sorted records, so the order of
completion never shows in the output). ``open_executor("dask://HOST:PORT")`` connects to a running Dask
scheduler; its workers need rollcam installed (the same version) and, with ``worker_writes``, the output
folder mounted at the same path.

Local pool workers die with their driver, even one killed with ``kill -9``: on Linux the kernel sends them
SIGKILL when it goes (``PR_SET_PDEATHSIG``), and everywhere a watchdog thread in each worker exits it once
its parent is gone. Each worker holds a shared lock on the output folder's worker lock file, so a rerun can
tell that workers of an earlier run are still writing and waits for them instead of racing them.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any

from rollcam.common.errors import ConfigError, RollcamError, require
from rollcam.common.files import acquire_lock
from rollcam.common.lifecycle import Deadline

from .plan import Task

TaskFn = Callable[[Task], Any]


class InlineExecutor:
    """Runs tasks one after another in this process (``--workers 1``)."""

    name = "inline"
    workers = 1
    remote = False

    def map_unordered(self, fn: TaskFn, tasks: Iterable[Task]) -> Iterator[Any]:
        """Results in task order."""
        for task in tasks:
            yield fn(task)

    def close(self) -> None:
        """Nothing to release."""


PR_SET_PDEATHSIG = 1  # from <linux/prctl.h>
PARENT_POLL_S = 0.25
"""How often a worker's watchdog looks for its parent (the portable fallback to PR_SET_PDEATHSIG)."""
LEFTOVER_WAIT_S = 10.0
"""How long a new pool waits for workers of an earlier, killed run to exit before refusing to start."""
_held: list[int | None] = []  # the worker's lock descriptor, kept open (so held) for the life of the process


def die_with_parent(parent_pid: int, *, deathsig: bool = True, poll_s: float = PARENT_POLL_S) -> None:
    """Make this process exit when ``parent_pid`` (its parent) does, however the parent ends.

    Linux: the kernel sends SIGKILL when the parent thread that started this process exits
    (``PR_SET_PDEATHSIG``; pools are started from the thread that submits, which outlives them). Everywhere:
    a daemon thread checks every ``poll_s`` seconds that the parent is still the one it was.
    """
    if deathsig and sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) != 0:
            raise OSError(ctypes.get_errno(), "prctl(PR_SET_PDEATHSIG) failed")
    if os.getppid() != parent_pid:  # the parent died before the death signal was armed
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(poll_s)
        os._exit(1)  # no cleanup: the driver is gone and nothing this process writes would be committed

    threading.Thread(target=watch, name="rollcam-parent-watchdog", daemon=True).start()


def init_worker(threads: int, parent_pid: int | None = None, lock_path: str | None = None,
                deathsig: bool = True) -> None:
    """Set up a pool worker: die with the driver, hold the folder's worker lock (shared), and take its share
    of the cores for the renderer's parallel kernels (numba)."""
    if parent_pid is not None:
        die_with_parent(parent_pid, deathsig=deathsig)
    if lock_path is not None:
        _held.append(acquire_lock(lock_path, "the dataset folder's worker lock", shared=True))
    import numba

    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))


def wait_for_leftover_workers(lock_path: str, wait_s: float = LEFTOVER_WAIT_S) -> None:
    """Return once no worker of an earlier run holds ``lock_path``; a ``RollcamError`` if some still do after
    ``wait_s`` seconds (workers die with their driver, so this only waits out a watchdog or a slow exit)."""
    deadline = Deadline(wait_s)
    while not _lock_free(lock_path):
        if deadline.expired:
            raise RollcamError(f"worker processes of an earlier run are still writing into "
                               f"{os.path.dirname(lock_path)!r} after {wait_s:g} s; stop them (they hold "
                               f"{lock_path!r}) and rerun")
        time.sleep(0.1)


def _lock_free(lock_path: str) -> bool:
    try:
        fd = acquire_lock(lock_path, "the dataset folder's worker lock")
    except BlockingIOError:
        return False
    if fd is not None:
        os.close(fd)
    return True


class PoolExecutor:
    """A local process pool; at most ``2 * workers`` tasks are in flight so memory stays bounded.

    Workers die with this process (see the module docstring). With ``lock_path`` each holds a shared lock on
    it, and the pool first waits (up to ``leftover_wait_s``) for workers of an earlier run to let go of it.
    Each worker runs the renderer's parallel kernels on ``threads_per_worker`` threads (default: the cores
    divided among the workers), so ``workers`` processes never oversubscribe the machine.
    """

    name = "local"
    remote = False

    def __init__(self, workers: int, threads_per_worker: int | None = None, *, lock_path: str | None = None,
                 leftover_wait_s: float = LEFTOVER_WAIT_S) -> None:
        if workers < 1:
            raise ConfigError(f"--workers must be >= 1, got {workers!r}")
        self.workers = workers
        threads = threads_per_worker or max(1, (os.cpu_count() or 1) // workers)
        if lock_path is not None:
            wait_for_leftover_workers(lock_path, leftover_wait_s)
        # Spawned, not forked: the renderer's OpenMP threads make fork() unsafe once a frame has been drawn.
        ctx = multiprocessing.get_context("spawn")
        self._pool: ProcessPoolExecutor | None = ProcessPoolExecutor(
            max_workers=workers, mp_context=ctx, initializer=init_worker,
            initargs=(threads, os.getpid(), lock_path))

    def map_unordered(self, fn: TaskFn, tasks: Iterable[Task]) -> Iterator[Any]:
        """Results as tasks finish."""
        assert self._pool is not None, "executor is closed"
        pending: set[Any] = set()
        it = iter(tasks)
        exhausted = False
        while True:
            while not exhausted and len(pending) < 2 * self.workers:
                task = next(it, None)
                if task is None:
                    exhausted = True
                else:
                    pending.add(self._pool.submit(fn, task))
            if not pending:
                return
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                yield fut.result()

    def close(self) -> None:
        """Stop the workers (unstarted tasks are cancelled); safe to call twice."""
        if self._pool is not None:
            pool, self._pool = self._pool, None
            pool.shutdown(wait=True, cancel_futures=True)


class DaskExecutor:
    """Tasks as Dask futures on a distributed cluster (one future per scene and time of day)."""

    name = "dask"
    remote = True

    def __init__(self, address: str) -> None:
        require("distributed", "dask[distributed]", "cluster", "--executor dask://...")
        from distributed import Client
        self.address = address
        try:
            self._client: Any = Client(address, timeout="20s")
        except OSError as exc:
            where = address.split("://", 1)[-1]
            raise ConfigError(f"--executor dask://{where}: cannot reach the scheduler ({exc})") from None
        self.workers = max(len(self._client.scheduler_info().get("workers", {})), 1)

    def map_unordered(self, fn: TaskFn, tasks: Iterable[Task]) -> Iterator[Any]:
        """Results as futures complete."""
        from distributed import as_completed

        futures = self._client.map(fn, list(tasks), pure=False)
        try:
            for fut in as_completed(futures):
                yield fut.result()
        finally:
            self._client.cancel([f for f in futures if not f.done()])

    def close(self) -> None:
        """Disconnect from the scheduler (the cluster keeps running); safe to call twice."""
        if self._client is not None:
            client, self._client = self._client, None
            client.close()


def open_executor(spec: str | None, workers: int = 1, threads_per_worker: int | None = None,
                  lock_path: str | None = None) -> InlineExecutor | PoolExecutor | DaskExecutor:
    """``None``: a pool of ``workers`` processes (in this process when 1); ``local``: a pool even of one;
    ``dask://HOST:PORT``: a cluster. ``lock_path``: the worker lock file of a local pool."""
    if spec in (None, ""):
        return InlineExecutor() if workers == 1 else PoolExecutor(workers, threads_per_worker, lock_path=lock_path)
    if spec == "local":
        return PoolExecutor(workers, threads_per_worker, lock_path=lock_path)
    if spec.startswith("dask://"):
        address = spec[len("dask://"):].rstrip("/")
        if not address:
            raise ConfigError(f"--executor {spec!r}: name the scheduler, e.g. dask://10.0.0.5:8786")
        return DaskExecutor(f"tcp://{address}" if "://" not in address else address)
    raise ConfigError(f"--executor {spec!r} is not 'local' or 'dask://HOST:PORT'")
