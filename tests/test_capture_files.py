"""rollcam capture on a failing disk: a record is whole or absent, each record has its images, each image its
record, and capture.json agrees with frames.jsonl, after ENOSPC or EIO at any step, a disk that fills at any
byte, a kill -9 and a power cut."""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import pytest
from fs_fakes import FailingFS, FullDiskFS
from rollcam.common.files import PART_SUFFIX
from rollcam.host.recording.capture import CAPTURE_INFO, FRAMES_LOG, capture, read_capture
from rollcam.host.sources import CameraSource, open_camera

URI = "emu:letsroll?size=64x36&scene=street&seed=1&speed=fast"
INSTANTS = 3


class PairList(CameraSource):
    """The same GS/RS pairs every time: capture runs without rendering."""

    supports_pairs = True

    def __init__(self, pairs) -> None:
        self.uri, self._pairs = URI, list(pairs)

    def read(self):
        pair = self.read_pair()
        return None if pair is None else pair[1]

    def read_pair(self):
        return self._pairs.pop(0) if self._pairs else None

    def _close(self) -> None:
        pass


@pytest.fixture(scope="module")
def pairs():
    with open_camera(URI) as src:
        return [src.read_pair() for _ in range(INSTANTS)]


def run_capture(pairs, out: Path, fs) -> BaseException | None:
    try:
        capture(PairList(pairs), out, INSTANTS, shutter="both", overwrite=True, progress=False, fs=fs)
    except OSError as exc:
        return exc
    return None


def check_folder(out: Path) -> int:
    """Assert the capture folder is consistent; return how many instants it kept."""
    if not out.exists():
        return 0
    names = {p.name for p in out.iterdir()}
    assert not [n for n in names if n.endswith(PART_SUFFIX)], names
    images = {n for n in names if n.endswith(".png")}
    if FRAMES_LOG not in names:
        assert not images, names
        return 0
    data = (out / FRAMES_LOG).read_bytes()
    assert data == b"" or data.endswith(b"\n"), data[-80:]
    records = [json.loads(line) for line in data.splitlines()]  # every line whole: no torn record at all
    assert {r["file"] for r in records} == images  # a record for every image, an image for every record
    for r in records:
        img = cv2.imread(str(out / r["file"]), cv2.IMREAD_UNCHANGED)
        assert img is not None and img.shape == (36, 64, 3), r["file"]
    assert len(records) % 2 == 0  # GS/RS pairs go in whole
    if CAPTURE_INFO in names:
        info = json.loads((out / CAPTURE_INFO).read_text())
        if "frames" in info:  # written when the capture ended: it must agree with the log
            assert (info["frames"], info["images"]) == (len(records) // 2, len(records)), info
        assert read_capture(out)[0]["frames"] == len(records) // 2
    return len(records) // 2


def test_clean_capture_reads_back(pairs, tmp_path: Path):
    out = tmp_path / "cap"
    assert run_capture(pairs, out, FailingFS()) is None
    assert check_folder(out) == INSTANTS
    info, records = read_capture(out)
    assert info["complete"] is True and info["frames"] == INSTANTS and len(records) == 2 * INSTANTS


@pytest.mark.parametrize("err", [errno.ENOSPC, errno.EIO])
def test_a_failure_at_every_write_step_keeps_the_folder_consistent(pairs, tmp_path: Path, err: int):
    probe = FailingFS()
    run_capture(pairs, tmp_path / "probe", probe)
    kept = []
    for k in range(1, probe.steps + 1):
        out = tmp_path / f"k{k}"
        fs = FailingFS(k, err)
        exc = run_capture(pairs, out, fs)
        assert exc is not None and exc.errno == err, (k, fs.failed)  # the first error is the one reported
        kept.append(check_folder(out))
    assert kept[-1] == INSTANTS and kept[0] == 0 and kept == sorted(kept)


def fill_levels(pairs, tmp_path: Path, levels: int) -> dict[str, int]:
    probe = tmp_path / "probe"
    run_capture(pairs, probe, FullDiskFS(10**9))
    total = sum(p.stat().st_size for p in probe.iterdir()) + len(json.dumps({}))
    outcomes = {"complete": 0, "stopped": 0}
    for i in range(levels):
        capacity = round(i * 1.1 * total / (levels - 1))  # from an empty disk to one with room to spare
        out = tmp_path / f"fill{i}"
        exc = run_capture(pairs, out, FullDiskFS(capacity))
        check_folder(out)
        outcomes["stopped" if exc is not None else "complete"] += 1
        if exc is not None:
            assert exc.errno == errno.ENOSPC
    return outcomes


def test_a_disk_that_fills_at_125_levels(pairs, tmp_path: Path):
    outcomes = fill_levels(pairs, tmp_path, 125)
    assert outcomes["stopped"] > 50 and outcomes["complete"] >= 1


def test_power_cut_truncating_the_log_reads_back_whole_records(pairs, tmp_path: Path):
    out = tmp_path / "cap"
    run_capture(pairs, out, FailingFS())
    data = (out / FRAMES_LOG).read_bytes()
    for cut in [*range(0, len(data), 61), len(data) - 1, len(data)]:
        (out / FRAMES_LOG).write_bytes(data[:cut])
        info, records = read_capture(out)
        assert len(records) == data[:cut].count(b"\n")
        assert all((out / r["file"]).is_file() for r in records)
        assert info["images"] == len(records)


@pytest.mark.skipif(os.name != "posix", reason="sends SIGKILL")
def test_kill_9_keeps_whole_records_of_existing_images(tmp_path: Path):
    out = tmp_path / "cap"
    code = ("import sys; from rollcam.host.cli import main; sys.exit(main(['capture', sys.argv[1], '--frames', "
            "'100000', '--out', sys.argv[2], '--shutter', 'both']))")
    proc = subprocess.Popen([sys.executable, "-c", code, URI, str(out)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            log = out / FRAMES_LOG
            if log.exists() and log.read_bytes().count(b"\n") >= 6:
                break
            time.sleep(0.02)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read()
    info, records = read_capture(out)
    assert len(records) >= 6 and info["complete"] is False and "frames" in info
    assert all(cv2.imread(str(out / r["file"])) is not None for r in records)
    orphans = {p.name for p in out.glob("*.png")} - {r["file"] for r in records}
    assert len(orphans) <= 2  # at most the instant that was being written when the process died
