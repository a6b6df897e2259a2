"""The ``rollcam`` command line: capture, demo, list, bench wiring, exit codes, interrupted captures.

Small emulated streams keep these fast; subprocess tests run the installed console script (or
``python -m rollcam.host.cli`` where it is missing) exactly as a user would.
"""

from __future__ import annotations

import importlib.util
import io
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from rollcam.host import SourceError, open_camera
from rollcam.host.capture import FRAMES_LOG, CaptureInterrupted, Progress, capture
from rollcam.host.demo import run_demo
from rollcam.host.sources import CameraSource
from rollcam.sim.frame import Frame

URI = "emu:letsroll?size=320x180&scene=street&seed=1&speed=fast"
FIELDS = {"sequence", "shutter", "timestamp_ns", "line_time_ns", "exposure_ns", "readout", "width", "height",
          "format", "file", "objects"}
OBJECT_FIELDS = {"id", "class", "box_gs", "box_rs", "visible", "speed_mps"}


def rollcam_cmd() -> list[str]:
    script = Path(sys.executable).parent / "rollcam"
    return [str(script)] if script.exists() else [sys.executable, "-m", "rollcam.host.cli"]


def run(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*rollcam_cmd(), *args], capture_output=True, text=True, cwd=cwd, timeout=300)


def records(out: Path) -> list[dict]:
    lines = (out / FRAMES_LOG).read_text().splitlines()
    return [json.loads(line) for line in lines]


def leftovers(out: Path) -> list[str]:
    return [p.name for p in out.iterdir() if p.name.endswith(".part") or ".part." in p.name]


def test_help_lists_subcommands():
    res = run("--help")
    assert res.returncode == 0, res.stderr
    for cmd in ("demo", "list", "capture", "bench"):
        assert cmd in res.stdout


def test_no_command_is_usage_error():
    res = run()
    assert res.returncode == 2
    assert "Traceback" not in res.stderr


def test_capture_both_pairs_same_instant(tmp_path: Path):
    out = tmp_path / "caps"
    res = run("capture", URI, "--frames", "3", "--out", str(out), "--shutter", "both", "--json")
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    assert summary["frames"] == 3 and summary["images"] == 6 and summary["complete"] is True
    assert Path(summary["out"]) == out and summary["seconds"] >= 0
    recs = records(out)
    assert [(r["sequence"], r["shutter"]) for r in recs] == [
        (i, s) for i in range(3) for s in ("global", "rolling")]
    for r in recs:
        assert set(r) >= FIELDS
        assert (r["width"], r["height"]) == (320, 180)
        assert r["file"] == f"{r['sequence']:06d}_{'gs' if r['shutter'] == 'global' else 'rs'}.png"
        img = cv2.imread(str(out / r["file"]), cv2.IMREAD_UNCHANGED)
        assert img is not None and img.shape == (180, 320, 3)
        for o in r["objects"]:
            assert set(o) >= OBJECT_FIELDS
            for key in ("box_gs", "box_rs"):
                assert o[key] is None or (len(o[key]) == 4 and o[key][0] <= o[key][2] and o[key][1] <= o[key][3])
    for gs, rs in zip(recs[::2], recs[1::2], strict=True):
        assert gs["timestamp_ns"] == rs["timestamp_ns"] and gs["exposure_ns"] == rs["exposure_ns"]
        assert gs["line_time_ns"] == 0 and rs["line_time_ns"] > 0
        gs_boxes = {o["id"]: o["box_gs"] for o in gs["objects"]}
        rs_boxes = {o["id"]: o["box_gs"] for o in rs["objects"] if o["box_gs"] is not None}
        assert rs_boxes and rs_boxes == gs_boxes  # the same instant's GS truth, whichever frame carries it
        assert any(o["box_rs"] != o["box_gs"] for o in rs["objects"])  # fast walkers: RS differs
    info = json.loads((out / "capture.json").read_text())
    assert info["source"]["uri"] == URI and info["source"]["width"] == 320
    assert info["command"][:3] == ["rollcam", "capture", URI]
    assert info["complete"] is True and info["frames"] == 3
    assert not leftovers(out)


def test_capture_default_shutter_jpg_and_overwrite(tmp_path: Path):
    out = tmp_path / "c"
    res = run("capture", URI, "--frames", "2", "--out", str(out), "--format", "jpg")
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in out.glob("*.jpg")) == ["000000_rs.jpg", "000001_rs.jpg"]
    assert all(r["shutter"] == "rolling" for r in records(out))

    again = run("capture", URI, "--frames", "1", "--out", str(out))
    assert again.returncode == 2
    assert "rollcam: error:" in again.stderr and "--overwrite" in again.stderr and "Traceback" not in again.stderr
    assert len(records(out)) == 2  # untouched

    (out / "notes.txt").write_text("keep me")
    res = run("capture", URI, "--frames", "1", "--out", str(out), "--overwrite", "--shutter", "global")
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in out.iterdir()) == ["000000_gs.png", "capture.json", "frames.jsonl", "notes.txt"]
    (rec,) = records(out)
    assert rec["shutter"] == "global" and rec["line_time_ns"] == 0


@pytest.mark.parametrize("uri, words", [
    ("emu:nosuchsensor", "no sensor named 'nosuchsensor'"),
    ("bogus:thing", "scheme 'bogus' is not supported"),
    ("emu:letsroll?colour=red", "unknown option"),
    ("emu:letsroll?size=12by7", "size"),
    ("not-a-uri", "is not a URI"),
    ("emu:letsroll?size=160x90&exposure_us=nan", "exposure_us"),
    ("emu:letsroll?size=160x90&exposure_us=inf", "exposure_us"),
    ("emu:letsroll?size=160x90&fps=1e-12", "below the minimum"),
    ("emu:letsroll?size=160x90&seed=-1", "seed"),
    ("emu:letsroll?size=160x90&frames=0", "frames"),
    ("emu:letsroll?size=160x90&start_ns=-5", "start_ns"),
    ("emu:letsroll?size=160x90&ego=rocket", "ego-motion 'rocket'"),
    ("emu:letsroll?size=160x90&gain=0", "gain"),
])
def test_bad_source_is_exit_2_without_traceback(tmp_path: Path, uri: str, words: str):
    res = run("capture", uri, "--frames", "1", "--out", str(tmp_path / "x"))
    assert res.returncode == 2
    assert res.stderr.startswith("rollcam: error:") and words in res.stderr
    assert "Traceback" not in res.stderr
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("frames", ["0", "-3", "ten", "1.5"])
def test_bad_frames_is_exit_2(tmp_path: Path, frames: str):
    res = run("capture", URI, "--frames", frames, "--out", str(tmp_path / "x"))
    assert res.returncode == 2
    assert "--frames" in res.stderr and "Traceback" not in res.stderr


def test_list_json():
    res = run("list", "--json")
    assert res.returncode == 0, res.stderr
    data = json.loads(res.stdout)
    by_name = {s["name"]: s for s in data["emulated"]}
    assert {"letsroll", "imx219", "ov9281"} <= set(by_name)
    lr = by_name["letsroll"]
    assert lr["shutter"] == "rolling" and lr["default_mode"] == "1920x1080" and lr["line_time_ns"] == 30864
    assert lr["fps"] == pytest.approx(30.0) and lr["uri"] == "emu:letsroll"
    assert by_name["ov9281"]["shutter"] == "global"
    for key in ("v4l2", "oak", "usb"):  # each device section lists devices or says why there are none
        assert data[key]["devices"] or data[key]["note"]
    table = run("list")
    assert table.returncode == 0 and "letsroll" in table.stdout and "OAK devices" in table.stdout


def test_bench_wiring():
    if importlib.util.find_spec("rollcam.benchmarks.bench") is None:
        res = run("bench", "--quick")
        assert res.returncode == 1
        assert "rollcam.benchmarks.bench" in res.stderr and "Traceback" not in res.stderr
    else:
        res = run("bench", "--help")
        assert res.returncode == 0 and "rollcam bench" in res.stdout


def test_unknown_argument_is_exit_2():
    res = run("list", "--bogus")
    assert res.returncode == 2 and "--bogus" in res.stderr


def test_demo_writes_video_and_contact_sheet(tmp_path: Path):
    result = run_demo(tmp_path / "demo", seconds=0.2, size=(320, 180), progress=False)
    assert result.frames == 6 and result.pedestrians > 0 and result.mean_shift_px > 0
    cap = cv2.VideoCapture(str(result.video))
    try:
        assert cap.isOpened()
        n = 0
        while True:
            ok, img = cap.read()
            if not ok:
                break
            n += 1
            assert img.shape[1] == 320
    finally:
        cap.release()
    assert n == 6
    sheet = cv2.imread(str(result.contact_sheet))
    assert sheet is not None and sheet.shape[1] > 2 * 320
    assert not leftovers(tmp_path / "demo")


def test_demo_cli(tmp_path: Path):
    res = run("demo", "--out", str(tmp_path / "d"), "--seconds", "0.1", "--size", "320x180")
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "d" / "demo_rs.mp4").stat().st_size > 0
    assert (tmp_path / "d" / "contact_sheet.png").stat().st_size > 0
    assert "pedestrians" in res.stdout and "demo_rs.mp4" in res.stdout


class _InterruptAfter(CameraSource):
    """Delegates to a real source and raises KeyboardInterrupt (as Ctrl-C would) on read number k + 1."""

    supports_pairs = True

    def __init__(self, inner: CameraSource, k: int) -> None:
        self.inner, self.k, self.n, self.uri = inner, k, 0, inner.uri

    def _tick(self) -> None:
        self.n += 1
        if self.n > self.k:
            raise KeyboardInterrupt

    def read(self) -> Frame | None:
        self._tick()
        return self.inner.read()

    def read_pair(self) -> tuple[Frame, Frame] | None:
        self._tick()
        return self.inner.read_pair()

    def info(self) -> dict:
        return self.inner.info()


@pytest.mark.parametrize("shutter, per_frame", [(None, 1), ("both", 2)])
def test_interrupted_capture_keeps_complete_frames(tmp_path: Path, shutter: str | None, per_frame: int):
    k = 3
    out = tmp_path / "cap"
    with open_camera(URI) as inner, pytest.raises(CaptureInterrupted) as exc:
        capture(_InterruptAfter(inner, k), out, 10, shutter=shutter, progress=False)
    assert isinstance(exc.value, KeyboardInterrupt)
    assert exc.value.result.frames == k and not exc.value.result.complete
    recs = records(out)
    assert len(recs) == k * per_frame
    assert all((out / r["file"]).is_file() for r in recs)
    assert len(list(out.glob("*.png"))) == k * per_frame
    assert not leftovers(out)
    info = json.loads((out / "capture.json").read_text())
    assert info["frames"] == k and info["complete"] is False and info["interrupted"] is True


class _FailingEncode(CameraSource):
    """Pairs whose rolling frame cannot be stored as an image: the pair's GS image must not survive alone."""

    supports_pairs = True
    uri = "test:failing"

    def __init__(self, inner: CameraSource) -> None:
        self.inner = inner

    def read(self) -> Frame | None:
        return self.inner.read()

    def read_pair(self) -> tuple[Frame, Frame] | None:
        gs, rs = self.inner.read_pair()
        if gs.sequence == 1:
            bad = Frame(np.zeros((4, 4, 5), np.uint8), "XXXX", rs.sequence, rs.timestamp_ns, rs.line_time_ns,
                        rs.readout, rs.exposure_ns)
            return gs, bad
        return gs, rs


def test_failed_pair_leaves_no_orphan_image(tmp_path: Path):
    out = tmp_path / "cap"
    with open_camera(URI) as inner, pytest.raises(SourceError):
        capture(_FailingEncode(inner), out, 3, shutter="both", progress=False)
    assert [r["file"] for r in records(out)] == ["000000_gs.png", "000000_rs.png"]
    assert sorted(p.name for p in out.glob("*.png")) == ["000000_gs.png", "000000_rs.png"]


class _NoPairs(CameraSource):
    uri = "test:nopairs"

    def read(self) -> Frame | None:
        return None


def test_both_needs_pairs(tmp_path: Path):
    with pytest.raises(SourceError, match="paired"):
        capture(_NoPairs(), tmp_path / "x", 2, shutter="both")
    assert not (tmp_path / "x").exists()


def test_finite_source_ends_capture_early(tmp_path: Path):
    with open_camera(URI + "&frames=2") as src:
        result = capture(src, tmp_path / "x", 5, progress=False)
    assert result.frames == 2 and not result.complete
    assert len(records(tmp_path / "x")) == 2


def test_progress_line():
    t = iter([0.0, 1.0, 1.05, 2.0, 2.01])
    buf = io.StringIO()
    bar = Progress(4, label="capture", stream=buf, enabled=True, clock=lambda: next(t))
    bar.update(1)  # t=1.0: shown
    bar.update(2)  # t=1.05: under 0.1 s since the last refresh, skipped
    bar.update(3)  # t=2.0: shown
    bar.update(4)  # t=2.01: the last one is always shown
    bar.close()
    text = buf.getvalue()
    assert text.count("\r") == 3 and text.endswith("\n")
    assert "capture 1/4" in text and "ETA" in text and "capture 4/4" in text
    quiet = io.StringIO()
    Progress(4, label="x", stream=quiet).update(1)  # StringIO is not a TTY: nothing shown by default
    assert quiet.getvalue() == ""


@pytest.mark.skipif(os.name != "posix", reason="sends SIGINT")
def test_ctrl_c_exits_130_with_complete_log(tmp_path: Path):
    out = tmp_path / "cap"
    proc = subprocess.Popen([*rollcam_cmd(), "capture", URI, "--frames", "100000", "--out", str(out),
                             "--shutter", "both"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            log = out / FRAMES_LOG
            if log.exists() and log.read_text().count("\n") >= 4:
                break
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "interrupted" in err
    recs = records(out)
    assert len(recs) >= 4 and len(recs) % 2 == 0
    assert all((out / r["file"]).is_file() for r in recs)
    assert len(list(out.glob("*.png"))) == len(recs)
    assert not leftovers(out)
    assert json.loads((out / "capture.json").read_text())["interrupted"] is True
