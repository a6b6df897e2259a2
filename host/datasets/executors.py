"""Where dataset tasks run: in process, on a local process pool, or on a Dask cluster.

Each executor takes a picklable function of one ``Task`` and yields its results as tasks finish (any order:
the driver commits samples one by one and the final files are built from sorted records, so the order of
completion never shows in the output). ``open_executor("dask://HOST:PORT")`` connects to a running Dask
scheduler; its workers need rollcam installed (the same version) and, with ``worker_writes``, the output
folder mounted at the same path.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any

from rollcam.common.errors import ConfigError, require

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


def _init_worker(threads: int) -> None:
    """Give each worker process its share of the cores for the renderer's parallel kernels (numba)."""
    import numba

    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))


class PoolExecutor:
    """A local process pool; at most ``2 * workers`` tasks are in flight so memory stays bounded.

    Each worker runs the renderer's parallel kernels on ``threads_per_worker`` threads (default: the cores
    divided among the workers), so ``workers`` processes never oversubscribe the machine.
    """

    name = "local"
    remote = False

    def __init__(self, workers: int, threads_per_worker: int | None = None) -> None:
        if workers < 1:
            raise ConfigError(f"--workers must be >= 1, got {workers!r}")
        self.workers = workers
        threads = threads_per_worker or max(1, (os.cpu_count() or 1) // workers)
        # Spawned, not forked: the renderer's OpenMP threads make fork() unsafe once a frame has been drawn.
        ctx = multiprocessing.get_context("spawn")
        self._pool: ProcessPoolExecutor | None = ProcessPoolExecutor(
            max_workers=workers, mp_context=ctx, initializer=_init_worker, initargs=(threads,))

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


def open_executor(spec: str | None, workers: int = 1,
                  threads_per_worker: int | None = None) -> InlineExecutor | PoolExecutor | DaskExecutor:
    """``None``: a pool of ``workers`` processes (in this process when 1); ``local``: a pool even of one;
    ``dask://HOST:PORT``: a cluster."""
    if spec in (None, ""):
        return InlineExecutor() if workers == 1 else PoolExecutor(workers, threads_per_worker)
    if spec == "local":
        return PoolExecutor(workers, threads_per_worker)
    if spec.startswith("dask://"):
        address = spec[len("dask://"):].rstrip("/")
        if not address:
            raise ConfigError(f"--executor {spec!r}: name the scheduler, e.g. dask://10.0.0.5:8786")
        return DaskExecutor(f"tcp://{address}" if "://" not in address else address)
    raise ConfigError(f"--executor {spec!r} is not 'local' or 'dask://HOST:PORT'")
