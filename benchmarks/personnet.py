"""``rollcam bench personnet``: the packaged detector (or any ``rollcam train`` model) against its targets.

Figures (the document's keys), each measured in this one run:

- ``file_mb``: the ONNX file's size (target <= 15 MB).
- ``ms_model`` / ``ms_detect``: median time per 640x360 frame on one CPU core (onnxruntime with one intra- and
  one inter-op thread): the network alone, and ``detect()`` with letterbox, decode and NMS on a rendered
  street frame (target ``ms_detect`` <= 15 ms); ``_min`` the fastest call. On a machine shared with other
  jobs the median is an upper bound and the min the closer estimate of the model's own cost.
- With ``--dataset`` (a rollcam dataset with val and test splits): ``iou``, the NMS IoU threshold of best
  mAP@0.5:0.95 on the validation split (from ``IOU_GRID``; the model's 3x3 heatmap peak pick already
  suppresses duplicates, so NMS only has to merge the odd pair, and a low threshold drops people standing
  behind one another); ``conf``, the score threshold of best F1 on the validation split at that ``iou`` (all
  subsets together: both are what ``personnet`` uses by default); ``test``, ``rollcam eval``'s table on the
  test split (per speed and shutter, at ``conf=0.01`` so mAP sees the whole precision-recall curve, and the
  chosen ``iou``); ``pooled``, the four test subsets together (targets mAP@0.5 >= 0.90, mAP@0.5:0.95 >= 0.60).
  Without ``--dataset`` the mAP targets do not apply.
- ``empty``: false positives per frame at the detector's threshold on street frames with no pedestrians at all
  (``emu:letsroll?pedestrians=0``, 1920x1080, rolling shutter: without walkers or ego-motion both shutters
  give the same picture), over scene seeds x 5 cameras x 3 times of day.
- ``flat``: the same on featureless 1920x1080 frames (``FLAT_LEVELS``, black to white, each clean and with a
  flat field's noise): what a camera's black start-up frames, a covered lens or a blown-out frame show; with
  ``max_score``, the highest score any of them reached (how far below the threshold the model stays).
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

TARGETS = {"file_mb": ("<=", 15.0), "ms_detect": ("<=", 15.0), "mAP50": (">=", 0.90), "mAP50_95": (">=", 0.60)}
SPEED_URI = "emu:letsroll?size=640x360&seed=1&pedestrians=20&frames=1"
EMPTY_URI = "emu:letsroll?scene=street&seed={seed}&camera={camera}&time={time}&pedestrians=0&shutter=rolling&frames=1"
EMPTY_TIMES = ("dawn", "noon", "dusk")
IOU_GRID = (0.45, 0.5, 0.55, 0.6, 0.65, 0.7, 0.75, 0.8, 0.85, 0.9)
"""NMS IoU thresholds tried on the validation split (0.45 is ``onnx:``'s default)."""
FLAT_LEVELS = (*range(0, 256, 16), 255)
"""Grey levels of the featureless frames (each once clean and once with noise of 2 DN)."""
EMPTY_SEED0 = 1000
"""First scene seed of the empty frames (scenes of their own, not those of any dataset)."""


def _times_ms(fn: Callable[[], Any], repeats: int) -> tuple[float, float]:
    """(median, min) ms of ``repeats`` calls after one warm-up (onnxruntime allocates on the first run)."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return round(float(np.median(times)), 2), round(float(np.min(times)), 2)


def speed(model: Path, repeats: int = 30) -> dict[str, float]:
    """Median (and min) ms per 640x360 street frame on one core: the network alone and the whole ``detect()``;
    the min is the better estimate of the cost on a machine that other jobs share."""
    import onnxruntime as ort
    from rollcam.host.detectors import load_detector
    from rollcam.host.sources import open_camera

    with open_camera(SPEED_URI) as cam:
        frame = cam.read().data
    opts = ort.SessionOptions()
    opts.intra_op_num_threads, opts.inter_op_num_threads = 1, 1
    sess = ort.InferenceSession(str(model), opts, providers=["CPUExecutionProvider"])
    inp = sess.get_inputs()[0]
    x = np.random.default_rng(0).random([int(d) for d in inp.shape], dtype=np.float32)
    det = load_detector(f"onnx:{model}?threads=1")
    try:
        model_ms = _times_ms(lambda: sess.run(None, {inp.name: x}), repeats)
        detect_ms = _times_ms(lambda: det.detect(frame), repeats)
    finally:
        det.close()
    return {"ms_model": model_ms[0], "ms_detect": detect_ms[0], "ms_model_min": model_ms[1],
            "ms_detect_min": detect_ms[1]}


def _suppress(dets: list[Any], iou: float) -> list[Any]:
    """``dets`` (found with NMS off) after class-aware NMS at ``iou``: what the detector returns at that ``iou``."""
    from rollcam.host.detectors.ops import nms
    from rollcam.host.evaluation.metrics import Dets

    out = []
    for d in dets:
        keep = nms(d.boxes, d.scores, d.classes, iou)
        out.append(Dets.of(d.boxes[keep], d.scores[keep], d.classes[keep]))
    return out


def scores(model: Path, dataset: Path) -> dict[str, Any]:
    """NMS IoU of best mAP@0.5:0.95 and best-F1 threshold on val; the test split's per-speed/shutter results and
    pooled metrics at that IoU. The detector runs once per image with NMS off (``iou=1``); each candidate IoU
    then applies NMS to the same detections, which is what the detector would return with that ``iou``."""
    from rollcam.host.detectors import load_detector
    from rollcam.host.evaluation.loaders import load_rollcam, run_detector
    from rollcam.host.evaluation.metrics import evaluate
    from rollcam.host.evaluation.report import build_document

    det = load_detector(f"onnx:{model}?conf=0.01&iou=1")
    keep = ("P", "R", "mAP50", "mAP50_95", "conf", "images", "boxes")
    try:
        found = {split: [(s, run_detector(det, s)) for s in load_rollcam(dataset, split)] for split in ("val", "test")}
    finally:
        det.close()

    def pooled(split: str, iou: float) -> dict[str, Any]:
        sets = found[split]
        return evaluate([e.truth for s, _ in sets for e in s.images],
                        [d for _, dets in sets for d in _suppress(dets, iou)])

    by_iou = {iou: pooled("val", iou) for iou in IOU_GRID}
    iou = max(IOU_GRID, key=lambda t: (round(float(by_iou[t]["mAP50_95"]), 6), -t))
    rows = [{"name": s.name, "speed": s.speed, "shutter": s.shutter,
             "metrics": evaluate([e.truth for e in s.images], _suppress(dets, iou))} for s, dets in found["test"]]
    table = build_document(rows, {"detector": f"onnx:{model.name}?conf=0.01&iou={iou}", "split": "test"})["results"]
    val = by_iou[iou]
    return {"iou": iou, "conf": round(float(val["conf"]), 3), "val": {k: val[k] for k in keep},
            "val_by_iou": {str(t): {k: round(float(m[k]), 4) for k in ("mAP50", "mAP50_95")}
                           for t, m in by_iou.items()},
            "pooled": {k: pooled("test", iou)[k] for k in keep}, "test": table}


def empty_frames(spec: str, scenes: int) -> dict[str, Any]:
    """False positives per frame of detector ``spec`` on street frames without pedestrians."""
    from rollcam.host.detectors import load_detector
    from rollcam.host.sources import open_camera

    det = load_detector(spec)
    counts = []
    try:
        for seed in range(EMPTY_SEED0, EMPTY_SEED0 + scenes):
            for camera in range(5):
                for tod in EMPTY_TIMES:
                    with open_camera(EMPTY_URI.format(seed=seed, camera=camera, time=tod)) as cam:
                        counts.append(len(det.detect(cam.read().data)))
        conf = det.conf
    finally:
        det.close()
    return false_positives(counts, conf)


def false_positives(counts: list[int], conf: float) -> dict[str, Any]:
    """The figures of detections per frame on frames that hold nobody: frames, fp_per_frame, frames_with_fp,
    max_fp (at ``conf``)."""
    c = np.array(counts)
    return {"frames": len(c), "conf": conf, "fp_per_frame": round(float(c.mean()), 4),
            "frames_with_fp": int((c > 0).sum()), "max_fp": int(c.max())}


def flat_frames(model: Path, conf: float, iou: float) -> dict[str, Any]:
    """Detections at ``conf`` on featureless frames (``FLAT_LEVELS``), and the highest score of any (found at
    conf 0.01)."""
    from rollcam.host.detectors import load_detector

    det = load_detector(f"onnx:{model}?conf=0.01&iou={iou}")
    rng = np.random.default_rng(0)
    counts, top = [], 0.0
    try:
        for level in FLAT_LEVELS:
            clean = np.full((1080, 1920, 3), level, np.uint8)
            noisy = np.clip(clean + rng.normal(0, 2, clean.shape), 0, 255).astype(np.uint8)
            for frame in (clean, noisy):
                scores = det.detect(frame).scores
                counts.append(int((scores >= conf).sum()))
                top = max(top, float(scores.max(initial=0.0)))
    finally:
        det.close()
    return false_positives(counts, conf) | {"max_score": round(top, 3)}


def personnet_bench(model: Path | None = None, dataset: Path | None = None, empty_scenes: int = 10,
                    say: Callable[[str], None] = lambda _msg: None) -> dict[str, Any]:
    """The figures and targets of ``model`` (default: the packaged ``personnet``) as one JSON document."""
    from rollcam.host.detectors import personnet

    packaged = model is None
    path = personnet.model_path() if packaged else Path(model)
    doc: dict[str, Any] = {"model": str(path), "file_mb": round(path.stat().st_size / 1e6, 3),
                           "sha256": hashlib.sha256(path.read_bytes()).hexdigest()}
    say("time per 640x360 frame, one core")
    doc.update(speed(path))
    if dataset is not None:
        say(f"val and test splits of {dataset}")
        doc["dataset"] = str(dataset)
        doc.update(scores(path, Path(dataset)))
    conf = doc.get("conf") or (personnet.default_conf() if packaged else 0.25)
    iou = doc.get("iou") or (personnet.default_iou() if packaged else 0.45)
    say(f"empty street frames at conf {conf}, NMS IoU {iou}")
    doc["empty"] = empty_frames(f"onnx:{path}?conf={conf}&iou={iou}", empty_scenes)
    say(f"featureless frames at conf {conf}, NMS IoU {iou}")
    doc["flat"] = flat_frames(path, conf, iou)
    doc["targets"] = targets(doc)
    return doc


def targets(doc: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Each target: value, op, limit, pass (None when it did not apply: no dataset scored)."""
    pooled = doc.get("pooled", {})
    vals = {"file_mb": doc["file_mb"], "ms_detect": doc["ms_detect"], "mAP50": pooled.get("mAP50"),
            "mAP50_95": pooled.get("mAP50_95")}
    out = {}
    for name, (op, limit) in TARGETS.items():
        v = vals[name]
        ok = None if v is None else bool(v <= limit if op == "<=" else v >= limit)
        out[name] = {"value": None if v is None else round(float(v), 4), "op": op, "limit": limit, "pass": ok}
    return out


def format_report(doc: dict[str, Any]) -> str:
    """The figures as text: size, speed, the per-speed/shutter table, empty- and flat-frame false positives,
    targets."""
    lines = [f"{doc['model']}: {doc['file_mb']} MB; per 640x360 frame on one core, median (min): model "
             f"{doc['ms_model']} ({doc['ms_model_min']}) ms, detect() {doc['ms_detect']} ({doc['ms_detect_min']}) ms"]
    if "test" in doc:
        from rollcam.host.evaluation.report import format_table

        lines.append(format_table({"detector": f"personnet (conf=0.01, iou={doc['iou']})", "split": "test",
                                   "results": doc["test"], "sets": {"pooled": doc["pooled"]}}))
        lines.append(f"NMS IoU of best val mAP@0.5:0.95: {doc['iou']}; best-F1 threshold on val: {doc['conf']}")
    e = doc["empty"]
    lines.append(f"empty street frames: {e['fp_per_frame']} false positives per frame at conf {e['conf']} "
                 f"({e['frames_with_fp']} of {e['frames']} frames with any, at most {e['max_fp']})")
    if "flat" in doc:  # documents from before the figure lack it
        f = doc["flat"]
        lines.append(f"featureless frames: {f['fp_per_frame']} false positives per frame at conf {f['conf']} "
                     f"({f['frames_with_fp']} of {f['frames']} frames with any; highest score {f['max_score']})")
    for name, t in doc["targets"].items():
        verdict = "n/a" if t["pass"] is None else "PASS" if t["pass"] else "FAIL"
        lines.append(f"target {name}: {t['value']} {t['op']} {t['limit']}: {verdict}")
    return "\n".join(lines)
