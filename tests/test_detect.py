"""``rollcam detect``: the loop, its files, ground-truth matching and a clean stop on Ctrl-C."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import wait_for
from interrupts import ctrl_c, interrupt
from rollcam.host.cli import main
from rollcam.host.detectors import PERSON, Detections
from rollcam.host.detectors.live import LOG, SUMMARY, VIDEO, DetectInterrupted, run_detect
from rollcam.host.evaluation.truthmatch import RunningPR, match

URI = "emu:imx219?size=320x180&seed=2&pedestrians=8&speed=fast"


class OracleDetector:
    """Returns the frame's RS truth boxes (so RS precision/recall are 1) and can stop like Ctrl-C."""

    name, input, class_names = "oracle", "bgr", {PERSON: "person"}

    def __init__(self, interrupt_at: int | None = None, compiled: bool = False) -> None:
        self.frame = None
        self.calls = 0
        self.interrupt_at = interrupt_at
        self.compiled = compiled  # interrupt as compiled code does: a SystemError raised from the Ctrl-C

    def detect(self, image: np.ndarray) -> Detections:
        self.calls += 1
        if self.calls == self.interrupt_at:
            ctrl_c(self.compiled)
        boxes = [o.box_rs for o in self.frame.objects if o.box_rs is not None and o.visible >= 0.25]
        return Detections(np.asarray(boxes).reshape(-1, 4), np.linspace(0.9, 0.5, len(boxes)), [PERSON] * len(boxes))

    def close(self) -> None:
        pass


class PeekingSource:
    """Wraps a source so the oracle sees the frame it is given."""

    def __init__(self, source, oracle) -> None:
        self.source, self.oracle = source, oracle
        self.uri, self.supports_pairs = source.uri, False

    def read(self):
        frame = self.source.read()
        self.oracle.frame = frame
        return frame

    def info(self):
        return self.source.info()


def test_detect_loop_writes_log_video_summary_and_scores_truth(tmp_path, rollcam_camera):
    oracle = OracleDetector()
    src = PeekingSource(rollcam_camera("imx219", size="320x180", seed=2, pedestrians=8, speed="fast"), oracle)
    result = run_detect(src, oracle, frames=3, out_dir=tmp_path)
    assert result.complete and result.frames == 3
    assert result.truth.totals["rs"].precision == 1.0 and result.truth.totals["rs"].recall == 1.0
    records = [json.loads(line) for line in (tmp_path / LOG).read_text().splitlines()]
    assert [r["sequence"] for r in records] == [0, 1, 2]
    assert records[1]["timestamp_ns"] > 0 and records[0]["line_time_ns"] > 0 and "objects" in records[0]
    assert records[0]["match"]["rs"]["fp"] == 0
    cap = cv2.VideoCapture(str(tmp_path / VIDEO))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 3
    cap.release()
    summary = json.loads((tmp_path / SUMMARY).read_text())
    assert summary["complete"] and summary["truth"]["rs"]["recall"] == 1.0 and summary["detect_ms"]["p50"] >= 0


@pytest.mark.parametrize("compiled", [False, True])
def test_interrupt_keeps_whole_records_and_a_playable_video(tmp_path, rollcam_camera, compiled):
    oracle = OracleDetector(interrupt_at=3, compiled=compiled)
    src = PeekingSource(rollcam_camera("imx219", size="320x180", seed=2), oracle)
    with pytest.raises(DetectInterrupted) as info:
        run_detect(src, oracle, frames=10, out_dir=tmp_path)
    assert info.value.result.frames == 2 and not info.value.result.complete
    assert len([json.loads(line) for line in (tmp_path / LOG).read_text().splitlines()]) == 2
    cap = cv2.VideoCapture(str(tmp_path / VIDEO))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 2
    cap.release()
    assert not json.loads((tmp_path / SUMMARY).read_text())["complete"]
    assert not list(tmp_path.glob("*.part*"))


def test_match_counts_ignored_boxes_apart():
    kept = np.array([[0, 0, 10, 20]], float)
    ignored = np.array([[50, 0, 52, 4]], float)
    c = match(np.array([[0, 0, 10, 19], [0, 0, 10, 19], [50, 0, 52, 4], [80, 80, 90, 90]], float), kept, ignored, 0.5)
    assert (c.tp, c.fp, c.fn, c.ignored) == (1, 2, 0, 1)
    pr = RunningPR()
    assert pr.summary().count("-") == 4


def test_cli_detect_json_summary(tmp_path, capsys):
    rc = main(["detect", URI, "--detector", "hog?stride=16", "--frames", "2", "--out", str(tmp_path), "--json",
               "--no-video"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["frames"] == 2 and out["complete"] and out["truth"]["frames"] == 2
    assert not (tmp_path / VIDEO).exists()
    assert main(["detect", URI, "--detector", "hog", "--frames", "1", "--out", str(tmp_path)]) == 2  # no overwrite
    assert main(["detect", URI, "--detector", "nope", "--frames", "1"]) == 2


@pytest.mark.skipif(sys.platform == "win32", reason="SIGINT to a child process")
@pytest.mark.parametrize("terminal", [False, True], ids=["rollcam-alone", "whole-process-group"])
def test_cli_ctrl_c_exits_130_with_files_intact(tmp_path, terminal):
    """Ctrl-C in a terminal signals the whole foreground process group (``terminal``: rollcam leads its own group
    and the SIGINT goes to the group, as a terminal sends it). On main ffmpeg was in that group, died of the same
    SIGINT and took detections.mp4 with it (issue 37); here it runs in its own and the video is finished."""
    exe = Path(sys.executable).with_name("rollcam")
    proc = subprocess.Popen([str(exe), "detect", URI, "--detector", "hog?stride=16", "--out", str(tmp_path)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env={**os.environ, "PYTHONUNBUFFERED": "1"},
                            start_new_session=terminal)
    log = tmp_path / LOG
    try:
        wait_for(lambda: log.exists() and log.read_text().count("\n") >= 3 and list(tmp_path.glob(f".{VIDEO}.*.part")),
                 120, "three frames logged with ffmpeg running")
    except AssertionError:
        proc.kill()
        raise
    _, err = interrupt(proc, group=terminal)
    assert proc.returncode == 130, err
    lines = log.read_text().splitlines()
    assert len(lines) >= 3 and all(json.loads(line)["detections"] is not None for line in lines)
    cap = cv2.VideoCapture(str(tmp_path / VIDEO))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) >= len(lines) - 1
    cap.release()
    if shutil.which("ffprobe"):  # the file is whole: ffprobe decodes every frame of it
        probe = subprocess.run(["ffprobe", "-v", "error", "-count_frames", "-select_streams", "v:0", "-show_entries",
                                "stream=nb_read_frames", "-of", "csv=p=0", str(tmp_path / VIDEO)],
                               capture_output=True, text=True, timeout=60, check=True)
        assert int(probe.stdout.strip()) >= len(lines) - 1, probe
    assert "interrupted after" in err.decode()
    assert not list(tmp_path.glob("*.part")) and not list(tmp_path.glob(".*.part"))


@pytest.mark.parametrize("where", ["file", "below-a-file"])
def test_out_that_is_a_file_is_one_line_exit_2(tmp_path, capsys, where):
    """Issue 37: main ended in a raw [Errno 17] / [Errno 20] with exit 1."""
    (tmp_path / "f").write_text("x")
    out = tmp_path / "f" if where == "file" else tmp_path / "f" / "sub"
    assert main(["detect", URI, "--detector", "hog?stride=16", "--frames", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("rollcam: error: --out ") and str(out) in err[0], err
    assert "must be a folder, not a file" in err[0] and "Errno" not in err[0]


def test_video_sink_reports_a_failed_write_once_and_never_blocks_the_loop(tmp_path, monkeypatch):
    """The sink's writer thread is a Worker: a write that fails is raised by close() as an OSError naming the
    file, the frames put after it are drained (a full queue would block the loop), and no file is left."""
    import rollcam.host.detectors.live as detect

    class Broken:
        def __init__(self, path, fps, size):
            pass

        def write(self, img):
            raise OSError("disk full")

        def abort(self):
            aborted.append(True)

    aborted: list[bool] = []
    monkeypatch.setattr(detect, "VideoWriter", Broken)
    sink = detect.VideoSink(tmp_path / "v.mp4", 30.0, max_queue=2)
    for _ in range(20):  # ten times the queue: blocks for ever unless the thread drains after the failure
        sink.put(np.zeros((8, 8, 3), np.uint8))
    with pytest.raises(OSError, match=r"v\.mp4 failed: disk full"):
        sink.close()
    sink.close()  # twice is harmless
    assert aborted == [True] and sink.frames == 0
