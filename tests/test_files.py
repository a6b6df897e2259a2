"""Files whole or absent: write_atomic and AppendLog under a failure at every step, torn lines, locks."""

from __future__ import annotations

import contextlib
import errno
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from fs_fakes import FailingFS, FullDiskFS
from rollcam.common.errors import ConfigError
from rollcam.common.files import (
    PART_SUFFIX,
    AppendLog,
    FileSystem,
    acquire_lock,
    complete_length,
    file_digest,
    file_matches,
    output_dir,
    part_path,
    part_target,
    read_jsonl,
    release_lock,
    repair_jsonl,
    write_atomic,
)


def parts(folder: Path) -> list[str]:
    return [p.name for p in folder.iterdir() if p.name.endswith(PART_SUFFIX)]


def steps_of(run) -> int:
    fs = FailingFS()
    run(fs)
    return fs.steps


@pytest.mark.parametrize("err", [errno.ENOSPC, errno.EIO])
def test_write_atomic_leaves_old_or_new_bytes_after_a_failure_at_any_step(tmp_path: Path, err: int):
    target = tmp_path / "doc.json"
    new = b"new " * 5000
    n = steps_of(lambda fs: write_atomic(tmp_path / "probe", new, fs))
    assert n == 6  # open, write, fsync, close, replace, fsync of the directory
    for k in range(1, n + 1):
        target.write_bytes(b"old")
        fs = FailingFS(k, err)
        with pytest.raises(OSError) as info:
            write_atomic(target, new, fs)
        assert info.value.errno == err, fs.failed
        assert target.read_bytes() == (new if fs.failed == "fsync_dir" else b"old"), fs.failed
        assert not parts(tmp_path), fs.failed


def test_write_atomic_on_a_disk_that_fills_at_every_byte_count(tmp_path: Path):
    target = tmp_path / "img.png"
    new = bytes(range(256)) * 8
    for capacity in range(0, len(new) + 2, 97):
        target.unlink(missing_ok=True)
        try:
            write_atomic(target, new, FullDiskFS(capacity))
        except OSError as exc:
            assert exc.errno == errno.ENOSPC and capacity < len(new)
            assert not target.exists()
        else:
            assert capacity >= len(new) and target.read_bytes() == new
        assert not parts(tmp_path)


def test_part_names_are_unique_and_map_back_to_their_target(tmp_path: Path):
    a, b = part_path(tmp_path / "x.png"), part_path(tmp_path / "x.png")
    assert a != b and a.parent == tmp_path and a.name.startswith(".x.png.") and a.name.endswith(PART_SUFFIX)
    assert part_target(a.name) == "x.png" and part_target("x.png.part") == "x.png"  # older runs' names too
    assert part_target("x.png") is None


def test_append_log_keeps_whole_lines_after_a_failure_at_any_step(tmp_path: Path):
    lines = [json.dumps({"i": i, "pad": "x" * 50}).encode() + b"\n" for i in range(4)]

    def run(fs: FileSystem) -> tuple[int, int | None]:
        path = tmp_path / "log.jsonl"
        path.unlink(missing_ok=True)
        committed = 0
        log = None
        try:
            log = AppendLog(path, truncate=True, fs=fs)
            for line in lines:
                log.append(line)
                committed += 1
        except OSError:
            pass
        finally:
            if log is not None:
                with contextlib.suppress(OSError):
                    log.close()
        return committed, None if log is None else log.size

    n = steps_of(run)
    for err in (errno.ENOSPC, errno.EIO):
        for k in range(1, n + 1):
            committed, size = run(FailingFS(k, err))
            path = tmp_path / "log.jsonl"
            data = path.read_bytes() if path.exists() else b""
            assert data == b"".join(lines[:committed]), k  # exactly the appends that returned
            assert size in (None, len(data))


def test_append_log_rolls_a_short_write_back(tmp_path: Path):
    path = tmp_path / "log.jsonl"
    line = b'{"a": 1}\n'
    with AppendLog(path, truncate=True, fs=FullDiskFS(len(line) + 4)) as log:
        log.append(line)
        with pytest.raises(OSError) as info:
            log.append(line)  # 4 bytes fit: a short write, then ENOSPC
        assert info.value.errno == errno.ENOSPC and log.size == len(line)
    assert path.read_bytes() == line


class NoTruncateFS(FullDiskFS):
    def ftruncate(self, fd, length):
        raise OSError(errno.EIO, "I/O error")


def test_a_torn_line_left_by_a_failed_rollback_is_skipped_and_repaired(tmp_path: Path):
    path = tmp_path / "log.jsonl"
    log = AppendLog(path, truncate=True, fs=NoTruncateFS(12))
    log.append(b'{"a": 1}\n')
    with pytest.raises(OSError):
        log.append(b'{"b": 2}\n')
    assert log.size is None  # the tail is unknown: no more appends
    with pytest.raises(OSError, match="unusable"):
        log.append(b'{"c": 3}\n')
    log.close()
    assert path.read_bytes() == b'{"a": 1}\n{"b'
    assert read_jsonl(path) == [{"a": 1}]
    with AppendLog(path) as again:  # opening to append repairs the tail first
        again.append(b'{"c": 3}\n')
    assert read_jsonl(path) == [{"a": 1}, {"c": 3}]


def test_power_loss_at_every_byte_of_a_log_keeps_a_prefix_of_whole_records(tmp_path: Path):
    records = [{"i": i, "file": f"{i:06d}.png", "pad": "é" * i} for i in range(5)]
    data = b"".join(json.dumps(r, ensure_ascii=False).encode() + b"\n" for r in records)
    path = tmp_path / "frames.jsonl"
    for cut in range(len(data) + 1):
        path.write_bytes(data[:cut])  # what the disk holds after a power cut at that byte
        got = read_jsonl(path)
        assert got == records[: len(got)] and len(got) == data[:cut].count(b"\n")
        removed = repair_jsonl(path)
        assert path.read_bytes() == data[: complete_length(data[:cut])] and removed == cut - len(path.read_bytes())


def test_damage_before_the_last_line_is_an_error_naming_the_line(tmp_path: Path):
    path = tmp_path / "frames.jsonl"
    path.write_bytes(b'{"a": 1}\nnot json\n{"b": 2}\n')
    with pytest.raises(ValueError, match="line 2"):
        read_jsonl(path)


def test_file_digest_catches_truncation_and_changed_bytes(tmp_path: Path):
    p = tmp_path / "img.png"
    data = os.urandom(5000)
    p.write_bytes(data)
    digest = file_digest(data)
    assert file_matches(p, digest)
    p.write_bytes(data[:4000])
    assert not file_matches(p, digest)
    p.write_bytes(data[:-1] + bytes([data[-1] ^ 1]))
    assert not file_matches(p, digest)
    assert not file_matches(tmp_path / "gone.png", digest)


@pytest.mark.skipif(os.name != "posix", reason="flock")
def test_lock_held_by_another_process_is_refused_at_once(tmp_path: Path):
    lock = tmp_path / ".lock"
    code = ("import sys, time; from rollcam.common.files import acquire_lock; "
            f"fd = acquire_lock({str(lock)!r}, 'x', shared=True); print('held', flush=True); sys.stdin.read()")
    proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "held"
        with pytest.raises(BlockingIOError, match="the dataset folder is in use"):
            acquire_lock(lock, "the dataset folder")
        os.close(acquire_lock(lock, "x", shared=True))  # shared holders do not exclude each other
    finally:
        proc.stdin.close()
        proc.wait(timeout=30)
    os.close(acquire_lock(lock, "the dataset folder"))  # released when its holder exits


@pytest.mark.skipif(os.name != "posix", reason="flock")
def test_a_removed_lock_file_is_gone_and_the_lock_can_be_taken_again(tmp_path: Path):
    lock = tmp_path / ".lock"
    fd = acquire_lock(lock, "x")
    with pytest.raises(BlockingIOError):
        acquire_lock(lock, "x")
    release_lock(fd, lock, remove=True)
    assert not lock.exists()
    fd = acquire_lock(lock, "x")  # a new file, locked
    assert lock.exists()
    release_lock(fd, lock)  # kept: a shared lock's file may still be held by others
    assert lock.exists()
    release_lock(None, lock, remove=True)  # nothing was held (no fcntl): nothing happens


def test_output_dir_makes_folders_and_refuses_a_file_in_the_way(tmp_path: Path):
    assert output_dir(tmp_path / "a" / "b") == tmp_path / "a" / "b" and (tmp_path / "a" / "b").is_dir()
    assert output_dir(tmp_path / "c", make=False) == tmp_path / "c" and not (tmp_path / "c").exists()
    (tmp_path / "f").write_text("x")
    with pytest.raises(ConfigError, match=r"--out '.*f' must be a folder, not a file$"):
        output_dir(tmp_path / "f")
    with pytest.raises(ConfigError, match=r"--out '.*f/sub' must be a folder, not a file: '.*f' is a file"):
        output_dir(tmp_path / "f" / "sub", make=False)


def test_write_figure_writes_a_png_atomically_and_closes_the_figure(tmp_path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from rollcam.common.files import write_figure

    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    write_figure(tmp_path / "f.png", fig, dpi=50)
    assert (tmp_path / "f.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert fig.number not in plt.get_fignums() and not list(tmp_path.glob("*.part*"))
