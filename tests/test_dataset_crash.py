"""rollcam dataset after crashes: workers die with a kill -9'd driver, a rerun cannot race leftovers or another
build, and a resume redoes a sample whose files were cut short behind its record."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import wait_for
from rollcam.common.errors import RollcamError
from rollcam.host.datasets import DatasetConfig, build_dataset
from rollcam.host.datasets.build import DRIVER_LOCK, WORKER_LOCK
from rollcam.host.datasets.executors import PoolExecutor
from test_dataset import SMALL, _tree

linux_only = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")


def _stat(pid: int, path: str = "stat") -> list[str] | None:
    try:
        text = Path(f"/proc/{pid}/{path}").read_text()
    except OSError:
        return None
    return text[text.rindex(")") + 2:].split()  # state, ppid, ... (the name may hold spaces)


def alive(pid: int) -> bool:
    """Whether any thread of process ``pid`` still runs. Its main thread may show as a zombie while the others
    are still exiting, and until the last one has, the process's files (and the locks on them) stay open."""
    st = _stat(pid)
    if st is None:
        return False
    if st[0] not in ("Z", "X"):
        return True
    try:
        tids = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return False
    return any((t := _stat(pid, f"task/{tid}/stat")) is not None and t[0] not in ("Z", "X") for tid in tids)


def children(pid: int) -> list[int]:
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            st = _stat(int(entry))
            if st is not None and int(st[1]) == pid and alive(int(entry)):
                out.append(int(entry))
    return out


def pool_workers(pid: int) -> list[int]:
    """The multiprocessing workers among a process's children (not its resource tracker)."""
    return [child for child in children(pid) if b"spawn_main" in _cmdline(child)]


def _cmdline(pid: int) -> bytes:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return b""


POOL = """
import os, sys, time
from concurrent.futures import ProcessPoolExecutor
import multiprocessing
from rollcam.host.datasets.executors import PoolExecutor, init_worker
lock, deathsig = sys.argv[1], sys.argv[2] == "1"
if deathsig:
    ex = PoolExecutor(2, 1, lock_path=lock)
    pool = ex._pool
else:  # the portable fallback alone: the parent-pid watchdog
    pool = ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn"), initializer=init_worker,
                               initargs=(1, os.getpid(), lock, False))
futures = [pool.submit(time.sleep, 120) for _ in range(2)]
print("submitted", flush=True)
time.sleep(600)
"""


@linux_only
@pytest.mark.parametrize("deathsig", [True, False], ids=["pdeathsig", "watchdog"])
def test_kill_9_of_the_driver_takes_its_workers_down(tmp_path: Path, deathsig: bool):
    lock = tmp_path / WORKER_LOCK
    driver = subprocess.Popen([sys.executable, "-c", POOL, str(lock), "1" if deathsig else "0"],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert driver.stdout.readline().strip() == "submitted"
        workers = wait_for(lambda: len(pool_workers(driver.pid)) == 2 and pool_workers(driver.pid), 60,
                           "two workers")
        # The workers hold the folder's worker lock: a new pool would wait for them.
        wait_for(lambda: _lock_held(lock), 60, "the workers to take the lock")
        driver.send_signal(signal.SIGKILL)
        driver.wait(timeout=10)
        wait_for(lambda: not any(alive(p) for p in workers), 5, f"workers {workers} to die with their driver")
        wait_for(lambda: not _lock_held(lock), 5, "the dead workers' lock to be free")  # (the kernel's last close)
    finally:
        if driver.poll() is None:
            driver.kill()
        for p in children(driver.pid):
            os.kill(p, signal.SIGKILL)


def _lock_held(lock: Path) -> bool:
    import fcntl

    if not lock.exists():
        return False
    fd = os.open(lock, os.O_RDWR)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)
    return False


HOLD = """
import sys, time
from rollcam.common.files import acquire_lock
fd = acquire_lock(sys.argv[1], "x", shared=sys.argv[2] == "shared")
print("held", flush=True)
time.sleep(float(sys.argv[3]))
"""


def _holder(lock: Path, mode: str, seconds: float) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(lock), mode, str(seconds)], stdout=subprocess.PIPE,
                            text=True)
    assert proc.stdout.readline().strip() == "held"
    return proc


@pytest.mark.skipif(os.name != "posix", reason="flock")
def test_a_new_pool_waits_for_leftover_workers_and_refuses_if_they_stay(tmp_path: Path):
    lock = tmp_path / WORKER_LOCK
    leftover = _holder(lock, "shared", 60)  # a worker of an earlier run, still writing
    try:
        with pytest.raises(RollcamError, match="still writing"):
            PoolExecutor(1, 1, lock_path=str(lock), leftover_wait_s=0.5)
    finally:
        leftover.kill()
        leftover.wait()
    brief = _holder(lock, "shared", 0.5)  # one that its watchdog takes down in a moment
    start = time.monotonic()
    ex = PoolExecutor(1, 1, lock_path=str(lock), leftover_wait_s=30)
    try:
        assert brief.poll() is not None or time.monotonic() - start >= 0.3  # it waited for the leftover
        assert list(ex.map_unordered(abs, [-3])) == [3]
    finally:
        ex.close()
        brief.wait()


@pytest.mark.skipif(os.name != "posix", reason="flock")
def test_a_second_build_into_the_same_folder_is_refused(tmp_path: Path):
    out = tmp_path / "ds"
    out.mkdir()
    other = _holder(out / DRIVER_LOCK, "exclusive", 60)
    try:
        with pytest.raises(RollcamError, match="another rollcam dataset is building"):
            build_dataset(SMALL, out)
    finally:
        other.kill()
        other.wait()
    assert sorted(p.name for p in out.iterdir()) == [DRIVER_LOCK]  # refused before writing anything


def test_resume_redoes_a_sample_whose_files_were_cut_short_behind_its_record(tmp_path: Path):
    out = tmp_path / "ds"
    first = build_dataset(SMALL, out)
    ref = _tree(out)
    images = sorted(out.glob("*/images/*/*.png"))
    labels = sorted(out.glob("*/labels/*/*.txt"))
    whole = images[0].read_bytes()
    images[0].write_bytes(whole[: len(whole) // 2])  # a power cut after the record went in
    labels[-1].write_bytes(labels[-1].read_bytes() + b"0 0.5 0.5 0.1 0.1\n")  # changed bytes, changed size
    again = build_dataset(SMALL, out)
    assert (again.resumed, again.redone, again.rendered) == (first.pairs - 2, 2, 2)
    assert images[0].read_bytes() == whole
    assert _tree(out) == ref
    untouched = build_dataset(SMALL, out)
    assert (untouched.resumed, untouched.redone, untouched.rendered) == (first.pairs, 0, 0)


def test_records_without_checksums_are_not_trusted(tmp_path: Path):
    import json

    out = tmp_path / "ds"
    build_dataset(SMALL, out)
    rec_path = next((out / "records").rglob("*.json"))
    rec = json.loads(rec_path.read_text())
    del rec["files"]  # a record from before records carried checksums
    rec_path.write_text(json.dumps(rec, sort_keys=True) + "\n")
    again = build_dataset(SMALL, out)
    assert (again.redone, again.rendered) == (1, 1)
    assert "files" in json.loads(rec_path.read_text())


@linux_only
@pytest.mark.slow
def test_kill_9_of_rollcam_dataset_then_rerun_gives_the_same_dataset(tmp_path: Path):
    cfg = DatasetConfig(size=(192, 108), scenes=3, frames=12, pedestrians=12, seed=7)
    ref = _tree(build_dataset(cfg, tmp_path / "ref").out_dir)
    out = tmp_path / "ds"
    cmd = [sys.executable, "-m", "rollcam.host.cli", "dataset", "--out", str(out), "--frames", "12", "--scenes",
           "3", "--size", "192x108", "--pedestrians", "12", "--seed", "7", "--workers", "2"]
    driver = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_for(lambda: len(list((out / "records").rglob("*.json"))) >= 2 if (out / "records").is_dir() else 0,
                 240, "two committed samples")
        workers = pool_workers(driver.pid)
        assert workers
        driver.send_signal(signal.SIGKILL)
        driver.wait(timeout=10)
        wait_for(lambda: not any(alive(p) for p in workers), 5, "the workers to die with their driver")
    finally:
        if driver.poll() is None:
            driver.kill()
    result = build_dataset(cfg, out, workers=2)
    assert result.resumed >= 2 and result.resumed + result.rendered == 12
    assert _tree(out) == ref
