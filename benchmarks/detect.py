"""``rollcam bench detect``: what ``rollcam detect`` costs besides the detector, and what each detector costs.

1. Loop overhead on ``emu:imx219`` at 1920x1080: ``run_detect`` with a detector that finds nothing, writing
   ``detections.jsonl`` and the annotated MP4 as the CLI does. Per frame it reports the capture time (the
   emulated sensor rendering the frame: the source's own cost) and the bookkeeping time (preview
   conversion, ground-truth matching, the JSON record, annotation and the hand-over to the encoder thread),
   which is the loop's overhead. Target: bookkeeping <= 5 ms per frame.
2. Per-frame time of each built-in detector (``hog``, ``ssdlite``, ``ssdlite`` with 3x2 tiles, ``personnet``, and any
   ``--onnx MODEL``) on a rendered street frame at 1920x1080 and 960x540: median of ``repeats`` calls after
   one warm-up call, single process, onnxruntime's default threads.
"""

from __future__ import annotations

import os
import platform
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from rollcam.host.detectors import PERSON, Detections, load_detector
from rollcam.host.detectors.live import run_detect
from rollcam.host.sources import open_camera

OVERHEAD_URI = "emu:imx219?size=1920x1080&seed=0"
DETECTOR_URI = "emu:letsroll?seed=2&pedestrians=30&camera=1&shutter=global&size={w}x{h}&frames=1"
DETECTORS = ("hog", "ssdlite", "ssdlite?tiles=3x2", "personnet")
SIZES = ((1920, 1080), (960, 540))
TARGET_BOOKKEEPING_MS = 5.0


class NullDetector:
    """Finds nothing, instantly: isolates the loop's own cost."""

    name, input, class_names = "null", "bgr", {PERSON: "person"}

    def detect(self, image: np.ndarray) -> Detections:
        return Detections.empty()

    def close(self) -> None:
        pass


def loop_overhead(frames: int = 20, uri: str = OVERHEAD_URI, video: bool = True) -> dict[str, Any]:
    """Median capture and bookkeeping ms per frame of the detect loop (first frame, the warm-up, dropped)."""
    with tempfile.TemporaryDirectory() as tmp, open_camera(uri) as source:
        result = run_detect(source, NullDetector(), frames=frames + 1, out_dir=Path(tmp), video=video)
    cap, book = np.asarray(result.capture_ms[1:]), np.asarray(result.bookkeeping_ms[1:])
    return {"uri": uri, "frames": frames, "video": video, "capture_ms_median": round(float(np.median(cap)), 3),
            "bookkeeping_ms_median": round(float(np.median(book)), 3),
            "bookkeeping_ms_p95": round(float(np.percentile(book, 95)), 3),
            "target_bookkeeping_ms": TARGET_BOOKKEEPING_MS,
            "meets_target": bool(np.median(book) <= TARGET_BOOKKEEPING_MS)}


def detector_times(specs: tuple[str, ...] = DETECTORS, sizes: tuple[tuple[int, int], ...] = SIZES,
                   repeats: int = 5) -> list[dict[str, Any]]:
    """Median per-frame detect() time of each detector at each size."""
    images = {}
    for w, h in sizes:
        with open_camera(DETECTOR_URI.format(w=w, h=h)) as cam:
            images[(w, h)] = cam.read().data
    rows = []
    for spec in specs:
        det = load_detector(spec)
        for (w, h), img in images.items():
            n = len(det.detect(img))  # warm-up (and allocation of the session's buffers)
            times = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                det.detect(img)
                times.append((time.perf_counter() - t0) * 1e3)
            rows.append({"detector": spec, "width": w, "height": h, "ms_median": round(float(np.median(times)), 2),
                         "ms_min": round(float(np.min(times)), 2), "detections": n})
        det.close()
    return rows


def detect_bench(quick: bool = False, onnx: tuple[str, ...] | list[str] = (),
                 say: Callable[[str], None] = lambda _msg: None) -> dict[str, Any]:
    """``rollcam bench detect``: the loop overhead and each detector's time, as one JSON document."""
    specs = DETECTORS + tuple(f"onnx:{m}" for m in onnx)
    machine = {"cpu_count": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version()}
    say("detect loop overhead")
    overhead = loop_overhead(frames=5 if quick else 20)
    say(f"detectors {', '.join(specs)}")
    times = detector_times(specs, repeats=2 if quick else 5)
    return {"machine": machine, "loop_overhead": overhead, "detectors": times}


def format_detect_bench(doc: dict[str, Any]) -> str:
    """The detect bench as plain text."""
    o = doc["loop_overhead"]
    lines = [f"detect loop on {o['uri']} ({o['frames']} frames, with MP4): capture {o['capture_ms_median']:.1f} "
             f"ms/frame (the emulator rendering), bookkeeping {o['bookkeeping_ms_median']:.2f} ms/frame median, "
             f"p95 {o['bookkeeping_ms_p95']:.2f} (target <= {TARGET_BOOKKEEPING_MS:g}: "
             f"{'met' if o['meets_target'] else 'NOT met'})",
             f"{'detector':24} {'size':>10} {'ms/frame':>9} {'dets':>5}"]
    lines += [f"{r['detector']:24} {r['width']:>5}x{r['height']:<4} {r['ms_median']:9.1f} {r['detections']:5d}"
              for r in doc["detectors"]]
    return "\n".join(lines)
