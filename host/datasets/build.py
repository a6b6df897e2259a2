"""``build_dataset``: plan, render (on any executor), commit sample by sample, then write the final files.

Resumable and atomic: every file goes in durably via a temporary name and a rename, and a sample's record is
written after its files; a rerun with the same config skips samples whose record is there and whose files
still match the sizes and checksums it holds, and redoes the rest (overwriting whatever an interrupted sample
left). ``config.json`` pins the config: rerunning into the same folder with a different config is refused
unless ``overwrite``. One build at a time writes into a folder (``.rollcam-dataset.lock``, an advisory
``flock`` held for the whole build, the file removed when the build ends however it ends); pool workers die
with their driver and hold ``.rollcam-workers.lock``, so a rerun after a ``kill -9`` waits for any that are
still going instead of racing them.
"""

from __future__ import annotations

import functools
import json
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, TextIO

from rollcam.common.errors import ConfigError, RollcamError
from rollcam.common.files import acquire_lock, output_dir, release_lock, write_atomic

from ..progress import Progress
from ..sources import open_camera
from .executors import open_executor
from .footage import FootageConfig
from .layout import CARD_JSON, CARD_MD, finalize
from .plan import SHUTTERS, DatasetConfig, subset_name
from .sample import (
    RECORDS,
    SampleResult,
    commit_record,
    files_intact,
    read_records,
    record_relpath,
    remove_partials,
    run_task,
    write_files,
)

CONFIG_FILE = "config.json"
DRIVER_LOCK = ".rollcam-dataset.lock"
WORKER_LOCK = ".rollcam-workers.lock"
_LOCKS = (DRIVER_LOCK, WORKER_LOCK)


@dataclass
class BuildResult:
    """What a build did: pairs in the dataset, pairs rendered by this run, pairs found done, seconds, card."""

    out_dir: Path
    pairs: int
    rendered: int
    resumed: int
    redone: int  # committed samples whose files no longer matched their record, rendered again
    seconds: float
    executor: str
    workers: int
    card: dict[str, Any]

    def to_json(self) -> dict[str, Any]:
        """The summary ``rollcam dataset --json`` prints."""
        return {"out": str(self.out_dir), "pairs": self.pairs, "rendered": self.rendered, "resumed": self.resumed,
                "redone": self.redone, "seconds": round(self.seconds, 3),
                "pairs_per_s": round(self.rendered / self.seconds, 3) if self.seconds > 0 else None,
                "executor": self.executor, "workers": self.workers,
                "card": str(self.out_dir / CARD_JSON), "subsets": sorted(self.card["subsets"])}


def rollcam_version() -> str:
    """The installed rollcam version (recorded in dataset cards)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("rollcam")
    except PackageNotFoundError:
        return "unknown"


def _check_out(out: Path, cfg: DatasetConfig, overwrite: bool) -> dict[str, Any] | None:
    """Refuse an ``out`` that is a file, holds another dataset or other things (writes nothing); the config
    pinned in it, if any."""
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {str(out)!r} exists and is not a directory")
    if not out.is_dir():
        return None
    pinned = out / CONFIG_FILE
    if pinned.exists():
        have = json.loads(pinned.read_text())
        want = json.loads(json.dumps(cfg.to_json()))
        if have != want and not overwrite:
            diff = sorted(k for k in set(have) | set(want) if have.get(k) != want.get(k))
            raise ConfigError(f"{str(out)!r} holds a dataset built with other options (differing: {diff}); pass "
                              "--overwrite to replace it, or choose another --out")
        return have
    if any(p.name not in _LOCKS for p in out.iterdir()) and not overwrite:
        raise ConfigError(f"--out {str(out)!r} is not empty and holds no rollcam dataset; choose an empty folder")
    return None


def _prepare(out: Path, cfg: DatasetConfig, overwrite: bool) -> None:
    """Pin the config in ``out`` (clearing a dataset built with another one when ``overwrite``)."""
    have = _check_out(out, cfg, overwrite)
    want = json.loads(json.dumps(cfg.to_json()))
    if have == want:
        return
    if have is not None:
        _clear(out, have)
    write_atomic(out / CONFIG_FILE, (json.dumps(want, indent=1) + "\n").encode())


def _clear(out: Path, old_cfg: dict[str, Any]) -> None:
    """Remove what a dataset build writes (and nothing else in the folder)."""
    names = [RECORDS, CARD_JSON, CARD_MD, CONFIG_FILE]
    names += [subset_name(sp, sh) for sp in old_cfg.get("speeds", ()) for sh in SHUTTERS]
    for name in names:
        p = out / name
        if p.is_dir():
            shutil.rmtree(p)
        else:
            p.unlink(missing_ok=True)


def build_dataset(
    cfg: DatasetConfig | FootageConfig,
    out_dir: str | Path,
    *,
    workers: int = 1,
    executor: str | None = None,
    threads_per_worker: int | None = None,
    worker_writes: bool | None = None,
    overwrite: bool = False,
    progress: bool | None = None,
    stream: TextIO | None = None,
    on_commit: Callable[[SampleResult], None] | None = None,
    clock: Callable[[], float] = time.monotonic,
) -> BuildResult:
    """Build (or finish building) the dataset ``cfg`` describes in ``out_dir`` (emulated scenes, or footage).

    ``executor``: None (``workers`` processes, or this process when 1), ``local`` (a pool even of one) or
    ``dask://HOST:PORT``; ``threads_per_worker``: renderer threads of each local worker (default: an even
    share of the cores). ``worker_writes``: workers
    write image and label files themselves (default for local pools; on a cluster only when ``out_dir`` is
    shared storage mounted at the same path on every worker); otherwise they return the bytes and this
    process writes them. ``on_commit`` is called after each sample is committed (a seam for tests).
    """
    out = output_dir(Path(out_dir).resolve(), make=False)  # a file there: one line, exit 2, before any work
    tasks = cfg.plan()
    first = tasks[0].samples[0]
    with open_camera(cfg.sample_uri(first)):  # bad sensor, size or source options fail here, before any work
        pass
    _check_out(out, cfg, overwrite)  # a folder that would be refused gets no lock file either
    output_dir(out)
    try:
        lock = acquire_lock(out / DRIVER_LOCK, f"dataset folder {str(out)!r}")
    except BlockingIOError:
        raise RollcamError(f"another rollcam dataset is building into {str(out)!r} (it holds {DRIVER_LOCK}); "
                           "wait for it or choose another --out") from None
    try:
        return _build(cfg, out, tasks, workers=workers, executor=executor, threads_per_worker=threads_per_worker,
                      worker_writes=worker_writes, overwrite=overwrite, progress=progress, stream=stream,
                      on_commit=on_commit, clock=clock)
    finally:  # finished or interrupted, the folder keeps no empty lock file
        release_lock(lock, out / DRIVER_LOCK, remove=True)


def _build(cfg: DatasetConfig, out: Path, tasks: list[Any], *, workers: int, executor: str | None,
           threads_per_worker: int | None, worker_writes: bool | None, overwrite: bool, progress: bool | None,
           stream: TextIO | None, on_commit: Callable[[SampleResult], None] | None,
           clock: Callable[[], float]) -> BuildResult:
    _prepare(out, cfg, overwrite)
    remove_partials(out)
    planned = {s.key for t in tasks for s in t.samples}
    done, redone = set(), 0
    for key, rec in read_records(out).items():
        if key not in planned:
            continue
        if files_intact(out, rec):
            done.add(key)
        else:  # revoked: its files were cut short or changed after it was committed
            (out / record_relpath(key)).unlink(missing_ok=True)
            redone += 1
    todo = [replace(t, samples=tuple(s for s in t.samples if s.key not in done)) for t in tasks]
    todo = [t for t in todo if t.samples]
    n_todo = sum(len(t.samples) for t in todo)
    # Nothing left to render (a finished dataset rerun): no pool or cluster connection needed.
    ex = open_executor(executor if todo else None, workers if todo else 1, threads_per_worker,
                       lock_path=str(out / WORKER_LOCK))
    writes = (not ex.remote) if worker_writes is None else worker_writes
    fn = functools.partial(run_task, cfg, root=str(out) if writes and ex.name != "inline" else None)
    bar = Progress(n_todo, label=f"dataset ({ex.name} x{ex.workers})", stream=stream, enabled=progress,
                   unit="pair")
    start = clock()
    rendered = 0
    try:
        for results in ex.map_unordered(fn, todo):
            for result in results:
                if result.files:
                    write_files(out, result.files)
                commit_record(out, result)
                rendered += 1
                bar.update(rendered)
                if on_commit is not None:
                    on_commit(result)
    finally:
        bar.close()
        ex.close()
    records = {k: v for k, v in read_records(out).items() if k in planned}
    missing = planned - set(records)
    if missing:
        raise RollcamError(f"{len(missing)} planned sample(s) have no record after the run, e.g. {sorted(missing)[0]}")
    card = finalize(out, cfg, records, rollcam_version())
    return BuildResult(out, len(planned), rendered, len(done), redone, clock() - start, ex.name, ex.workers, card)
