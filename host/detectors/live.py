"""``rollcam detect SOURCE --detector NAME``: live detection on any source, logged and annotated.

The loop reads a frame, hands the detector its preview (BGR) or raw mosaic (detectors with ``input='raw'``),
or, with ``--detector insensor``, takes the detections the camera's in-sensor network made (each carried result
scored against the frame it came from: ``rollcam.host.detectors.insensor``), and shows fps, capture latency
and detector latency on one status line. With ``--out DIR`` it writes:

- ``detections.jsonl``: one record per frame (sequence, timestamps, line time, exposure, latencies,
  detections with box/score/class, and for synthetic sources the ground-truth objects and per-frame match
  counts). Each record goes to the file in one ``write`` on an ``O_APPEND`` descriptor, cut back if that
  write fails, so the log ends on a whole record whenever the run stops (a kill or power cut mid-write can
  leave a torn last line, which ``rollcam.common.files.read_jsonl`` skips).
- ``detections.mp4``: the frames with detections (green), RS truth (red) and GS truth (blue) drawn; encoded
  on a writer thread so encoding does not stall the loop, written as ``.part`` and renamed when complete
  (also after Ctrl-C).
- ``detect.json``: the run's summary (source, detector, frames, latency statistics, precision/recall).

For synthetic sources, detections are matched to the GS and RS ground truth and running precision and
recall are printed (``rollcam.host.evaluation.truthmatch``). Ctrl-C stops cleanly: what was written stays valid and the
command exits with status 130. The command line is ``rollcam.host.commands.detect``.
"""

from __future__ import annotations

import json
import queue
import time
from array import array
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from rollcam.common.errors import SourceError, is_interrupt
from rollcam.common.files import AppendLog, output_dir
from rollcam.common.lifecycle import Worker
from rollcam.sim.frame import Frame

from ..evaluation.truthmatch import RunningPR
from ..recording.video import VideoWriter
from ..sources import CameraSource
from . import Detections, Detector

LOG, VIDEO, SUMMARY = "detections.jsonl", "detections.mp4", "detect.json"
COLORS = {"det": (0, 255, 0), "rs": (0, 0, 255), "gs": (255, 128, 0)}
"""BGR colour of detections and of RS / GS truth boxes in the annotated video."""


class DetectionLog:
    """``detections.jsonl``: each record one whole line in one append, cut back if the write fails
    (``rollcam.common.files.AppendLog``)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._log = AppendLog(path, truncate=True)

    def write(self, record: dict[str, Any]) -> None:
        self._log.append((json.dumps(record, separators=(",", ":")) + "\n").encode("utf-8"))

    def close(self) -> None:
        """Flush to disk and close; safe to call twice."""
        self._log.close()


class VideoSink:
    """An MP4 written on a background thread (a ``Worker``) from a bounded queue (the loop only hands over
    images)."""

    def __init__(self, path: Path, fps: float, max_queue: int = 8) -> None:
        self.path, self.fps = path, fps
        self._queue: queue.Queue[np.ndarray | None] = queue.Queue(max_queue)
        self._writer: VideoWriter | None = None
        self.frames = 0
        # close() waits for the last frames to be encoded however long that takes: no join timeout
        self._worker = Worker(self._run, name="detect-video", join_timeout_s=None).start()

    def _run(self) -> None:
        try:
            while (img := self._queue.get()) is not None:
                if self._writer is None:
                    self._writer = VideoWriter(self.path, self.fps, (img.shape[1], img.shape[0]))
                self._writer.write(img)
                self.frames += 1
        except BaseException:  # the Worker keeps it for close(); keep draining so put() never blocks forever
            while self._queue.get() is not None:
                pass
            raise

    def put(self, image: np.ndarray) -> None:
        self._queue.put(image)

    def close(self) -> None:
        """Finish the file and move it into place; safe to call twice."""
        if self._worker.alive:
            self._queue.put(None)
        error = None
        try:
            self._worker.close()
        except BaseException as exc:  # the writer's failure, raised once
            error = exc
        if self._writer is not None:
            writer, self._writer = self._writer, None
            if error is None:
                writer.close()  # an OSError naming the file if ffmpeg failed
            else:
                writer.abort()  # a video cut short by a failed write is not kept under its final name
        if error is not None:
            raise OSError(f"writing {self.path} failed: {error}")


def annotate(image: np.ndarray, dets: Detections, frame: Frame, names: dict[int, str]) -> np.ndarray:
    """A copy of ``image`` with truth boxes (RS red, GS blue) under the detections (green, with scores)."""
    import cv2

    out = image.copy()
    for o in frame.objects or ():
        for kind, box in (("gs", o.box_gs), ("rs", o.box_rs)):
            if box is not None:
                cv2.rectangle(out, (int(box[0]), int(box[1])), (int(box[2]), int(box[3])), COLORS[kind], 1)
    for (x0, y0, x1, y1), s, c in zip(dets.boxes, dets.scores, dets.classes, strict=True):
        cv2.rectangle(out, (int(x0), int(y0)), (int(x1), int(y1)), COLORS["det"], 2)
        cv2.putText(out, f"{names.get(int(c), c)} {s:.2f}", (int(x0), max(int(y0) - 4, 10)),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.45, COLORS["det"], 1, cv2.LINE_AA)
    return out


def summary_stats(values: Sequence[float]) -> dict[str, float] | None:
    """Mean, median, p95 and max of per-frame latencies (ms), or None without any."""
    if not len(values):
        return None
    a = np.asarray(values)
    return {"mean": round(float(a.mean()), 3), "p50": round(float(np.median(a)), 3),
            "p95": round(float(np.percentile(a, 95)), 3), "max": round(float(a.max()), 3)}


@dataclass
class DetectResult:
    """What a run did: frame count, per-frame latencies (ms), truth matching, files, completion."""

    frames: int = 0
    detections: int = 0
    # array('d'): 8 bytes a value, so a day-long live run keeps its latencies in tens of MB, not hundreds
    capture_ms: array = field(default_factory=lambda: array("d"))
    detect_ms: array = field(default_factory=lambda: array("d"))
    bookkeeping_ms: array = field(default_factory=lambda: array("d"))
    seconds: float = 0.0
    truth: RunningPR | None = None
    complete: bool = False
    out_dir: Path | None = None

    @property
    def fps(self) -> float:
        return self.frames / self.seconds if self.seconds > 0 else 0.0

    def to_json(self) -> dict[str, Any]:
        return {"frames": self.frames, "detections": self.detections, "seconds": round(self.seconds, 3),
                "fps": round(self.fps, 3), "complete": self.complete,
                "capture_ms": summary_stats(self.capture_ms), "detect_ms": summary_stats(self.detect_ms),
                "bookkeeping_ms": summary_stats(self.bookkeeping_ms),
                "truth": self.truth.to_json() if self.truth is not None and self.truth.frames else None,
                "out_dir": None if self.out_dir is None else str(self.out_dir)}


class DetectInterrupted(KeyboardInterrupt):
    """Ctrl-C during ``run_detect``; carries the result of the frames done."""

    def __init__(self, result: DetectResult) -> None:
        super().__init__("interrupted")
        self.result = result


def _reader(source: CameraSource, shutter: str | None) -> Callable[[], Frame | None]:
    if shutter is None or source.info().get("shutter") == shutter:
        return source.read
    if not source.supports_pairs:
        raise SourceError(f"source {source.uri!r} cannot deliver {shutter}-shutter frames")
    return lambda: source.read_as(shutter)


def run_detect(source: CameraSource, detector: Detector, *, frames: int | None = None, out_dir: Path | None = None,
               shutter: str | None = None, video: bool = True, truth: RunningPR | None = None,
               status: Callable[[DetectResult, Detections], None] | None = None,
               clock: Callable[[], float] = time.perf_counter, meta: dict[str, Any] | None = None,
               correct: str | None = None) -> DetectResult:
    """Detect on up to ``frames`` frames of ``source`` (all when None), logging to ``out_dir`` if given;
    ``correct="gyro"`` unwarps each rolling-shutter frame from its IMU samples first, ``"flow"`` from its flow
    to the previous frame (``rollcam.host.correction.gyro``)."""
    from ..preview import frame_bgr

    result = DetectResult(truth=truth if truth is not None else RunningPR(), out_dir=out_dir)
    read = _reader(source, shutter)
    if correct is not None:
        from ..correction.gyro import correcting_reader

        read = correcting_reader(read, correct)
    log = sink = None
    if out_dir is not None:
        output_dir(out_dir)
        log = DetectionLog(out_dir / LOG)
        if video:
            sink = VideoSink(out_dir / VIDEO, float(source.info().get("fps") or 30.0))
    names = detector.class_names
    start = clock()
    try:
        while frames is None or result.frames < frames:
            t0 = clock()
            frame = read()
            t1 = clock()
            if frame is None:
                break
            t2 = clock()
            if detector.input == "device":  # the camera's own detections, each with the frame it came from
                pairs = detector.pair(frame)
                image = None
            else:
                image = frame.data if detector.input == "raw" else frame_bgr(frame)
                t2 = clock()
                pairs = [(frame, detector.detect(image))]
            t3 = clock()
            dets = Detections.empty()
            for src, dets in pairs:
                counts = result.truth.update(src, dets)
                if log is not None:
                    log.write(_record(src, dets, counts, (t1 - t0) * 1e3, (t3 - t2) * 1e3))
                if sink is not None and src.data.size:  # a metadata-only frame has no picture to draw on
                    sink.put(annotate(image if image is not None and image.ndim == 3 else frame_bgr(src), dets,
                                      src, names))
                result.detections += len(dets)
            t4 = clock()
            result.frames += 1
            result.capture_ms.append((t1 - t0) * 1e3)
            result.detect_ms.append((t3 - t2) * 1e3)
            result.bookkeeping_ms.append(((t2 - t1) + (t4 - t3)) * 1e3)
            result.seconds = clock() - start
            if status is not None:
                status(result, dets)
        result.complete = True
    except KeyboardInterrupt:
        raise DetectInterrupted(result) from None
    except Exception as exc:
        if is_interrupt(exc):  # Ctrl-C inside compiled code
            raise DetectInterrupted(result) from None
        raise
    finally:
        result.seconds = clock() - start
        try:
            if sink is not None:
                sink.close()
        finally:
            if log is not None:
                log.close()
            if out_dir is not None:
                _write_summary(out_dir, result, source, detector, meta or {})
    return result


def _record(frame: Frame, dets: Detections, counts: dict[str, Any] | None, capture_ms: float,
            detect_ms: float) -> dict[str, Any]:
    """One ``detections.jsonl`` record: the frame, its latencies, detections and truth matches."""
    rec: dict[str, Any] = {
        "sequence": frame.sequence, "timestamp_ns": frame.timestamp_ns, "shutter": frame.shutter,
        "line_time_ns": frame.line_time_ns, "exposure_ns": frame.exposure_ns,
        "width": frame.width, "height": frame.height, "capture_ms": round(capture_ms, 3),
        "detect_ms": round(detect_ms, 3), "detections": dets.to_json()}
    if frame.objects is not None:
        rec["objects"] = [o.to_json() for o in frame.objects]
        rec["match"] = {k: {"tp": c.tp, "fp": c.fp, "fn": c.fn} for k, c in (counts or {}).items()}
    return rec


def _write_summary(out_dir: Path, result: DetectResult, source: CameraSource, detector: Detector,
                   meta: dict[str, Any]) -> None:
    from rollcam.common.files import write_atomic

    info = {"source": source.info(), "detector": {"name": detector.name, "repr": repr(detector)}, **meta,
            **result.to_json()}
    write_atomic(out_dir / SUMMARY, (json.dumps(info, indent=2, default=str) + "\n").encode("utf-8"))


class StatusLine:
    """The live status on the one progress line: frames and their rate, capture and detector latency (mean of
    the last 30), detections, and running P/R with truth. Off when stderr is not a terminal unless ``enabled``."""

    def __init__(self, total: int | None = None, *, enabled: bool | None = None, stream: TextIO | None = None) -> None:
        from ..progress import Progress

        self.bar = Progress(total, label="detect", stream=stream, enabled=enabled, unit="frame")

    def __call__(self, result: DetectResult, dets: Detections) -> None:
        if not self.bar.enabled:
            return
        recent = slice(-30, None)
        capture_ms, detect_ms = np.mean(result.capture_ms[recent]), np.mean(result.detect_ms[recent])
        line = f"capture {capture_ms:6.1f} ms  detect {detect_ms:6.1f} ms  dets {len(dets):3d}"
        if result.truth is not None and result.truth.frames:
            line += "  " + result.truth.summary()
        self.bar.status(line, refresh=False)
        self.bar.update(result.frames)

    def close(self) -> None:
        self.bar.close()
