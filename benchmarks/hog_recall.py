"""Do the rendered walkers look like people? Recall of OpenCV's stock HOG people detector on them.

Renders global-shutter daylight frames of seeded street scenes from every camera at a few instants, keeps
the pedestrians a detector can fairly be asked to find (box >= ``min_height_px`` tall at full resolution,
not cut by the image border, at least ``min_visible`` of their pixels unoccluded) and runs
``cv2.HOGDescriptor`` with ``HOGDescriptor_getDefaultPeopleDetector()`` (Dalal-Triggs, INRIA-trained) on the
full-resolution frame. Detections are matched greedily (highest SVM score first) one-to-one to the kept
pedestrians at IoU >= 0.5.

HOG returns its 64x128 detection window, which frames the person loosely (an INRIA person is ~96 px tall
in that window). Each detection is shrunk by 15 % of its width on each side and 5 % of its height at top
and bottom before matching: the fixed shrink of OpenCV's own ``samples/python/peopledetect.py``.

Precision counts a detection as false when it matches no kept pedestrian and does not overlap (IoU >= 0.5)
one of the pedestrians left out of the evaluation (too small, truncated or occluded): those are neither
credited nor charged, as with the "ignore" boxes of the Caltech pedestrian benchmark.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.host.detectors.hog import SHRINK_H, SHRINK_W, HogDetector
from rollcam.sim.render import Renderer
from rollcam.sim.scenegen import DAYLIGHT, make_street_scene

HEIGHT_BINS_PX = (128, 160, 200, 256, 384)
"""Lower edges of the per-height-bin recall (the last bin is open-ended)."""

IOU_MIN = 0.5

Box = tuple[float, float, float, float]


def iou(a: Box, b: Box) -> float:
    """Intersection over union of two (x0, y0, x1, y1) boxes."""
    iw = min(a[2], b[2]) - max(a[0], b[0])
    ih = min(a[3], b[3]) - max(a[1], b[1])
    if iw <= 0 or ih <= 0:
        return 0.0
    inter = iw * ih
    return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)


def match_frame(dets: Sequence[tuple[Box, float]], kept: Sequence[Box],
                ignored: Sequence[Box]) -> tuple[list[bool], int, int]:
    """Greedy one-to-one matching of score-ordered detections to the kept boxes at IoU >= 0.5.

    Returns which kept boxes were found, the false-positive count and the count of detections that only
    match ignored boxes.
    """
    found = [False] * len(kept)
    fp = n_ign = 0
    for box, _score in dets:
        best, best_iou = -1, IOU_MIN
        for g, gt in enumerate(kept):
            if not found[g]:
                v = iou(box, gt)
                if v >= best_iou:
                    best, best_iou = g, v
        if best >= 0:
            found[best] = True
        elif any(iou(box, gt) >= IOU_MIN for gt in ignored):
            n_ign += 1
        else:
            fp += 1
    return found, fp, n_ign


def _bin_label(lo: int, hi: int | None) -> str:
    return f"{lo}-{hi}" if hi is not None else f"{lo}+"


def hog_recall(
    n_scenes: int = 10,
    seed: int = 0,
    width: int = 1920,
    height: int = 1080,
    min_height_px: float = 128,
    min_visible: float = 0.95,
    times: Sequence[str] = DAYLIGHT,
    frames_per_camera: int = 2,
    hit_threshold: float = 0.0,
    scale: float = 1.05,
    progress: Callable[[int, int], None] | None = None,
    *,
    n_pedestrians: int = 30,
    frame_spacing_s: float = 4.0,
    win_stride_px: int = 8,
    padding_px: int = 16,
) -> dict:
    """HOG people-detector recall on unoccluded, untruncated pedestrians of seeded daylight street scenes.

    Scene ``i`` uses seed ``seed + i`` and time of day ``times[i % len(times)]``; every camera of it is
    rendered global-shutter at ``frames_per_camera`` instants ``frame_spacing_s`` apart. Detection runs on
    the full-resolution frame. ``progress(done, total)`` is called after each frame. Returns a JSON-able dict.
    """
    if n_scenes < 1 or frames_per_camera < 1 or not times:
        raise ConfigError(f"need n_scenes >= 1, frames_per_camera >= 1 and some times of day, got "
                          f"{n_scenes!r}, {frames_per_camera!r}, {times!r}")
    hog = HogDetector(scale=scale, stride_px=win_stride_px, padding_px=padding_px, hit_threshold=hit_threshold)
    t_start = time.perf_counter()
    bins = [*HEIGHT_BINS_PX]
    heights: list[float] = []
    hits: list[bool] = []
    tods: list[str] = []
    n_fp = n_ign = n_det = n_frames = 0
    total = None
    for i in range(n_scenes):
        tod = times[i % len(times)]
        scene = make_street_scene(seed + i, time_of_day=tod, n_pedestrians=n_pedestrians, width=width,
                                  height=height)
        if total is None:
            total = n_scenes * len(scene.cameras) * frames_per_camera
        for cam in range(len(scene.cameras)):
            renderer = Renderer(scene, cam)
            for k in range(frames_per_camera):
                t_ns = int((1.0 + k * frame_spacing_s) * 1e9)
                res = renderer.render_lines(np.full(height, t_ns, np.int64))
                vis = res.truth.visible_fraction()
                kept: list[Box] = []
                ignored: list[Box] = []
                for o, box in enumerate(res.truth.boxes()):
                    if box is None or renderer.actor_classes[o] != "person":
                        continue
                    x0, y0, x1, y1 = box
                    inside = x0 >= 1.0 and y0 >= 1.0 and x1 <= width - 1.0 and y1 <= height - 1.0
                    if inside and y1 - y0 >= min_height_px and vis[o] >= min_visible:
                        kept.append(box)
                    else:
                        ignored.append(box)
                found_dets = hog.detect(res.image)
                dets = [(tuple(map(float, b)), float(sc)) for b, sc in zip(found_dets.boxes, found_dets.scores,
                                                                         strict=True)]
                found, fp, ign = match_frame(dets, kept, ignored)
                heights.extend(b[3] - b[1] for b in kept)
                hits.extend(found)
                tods.extend([tod] * len(kept))
                n_fp += fp
                n_ign += ign
                n_det += len(dets)
                n_frames += 1
                if progress is not None:
                    progress(n_frames, total)
    h = np.asarray(heights)
    hit = np.asarray(hits, bool)
    n_tp = int(hit.sum())
    per_bin = {}
    for j, lo in enumerate(bins):
        hi = bins[j + 1] if j + 1 < len(bins) else None
        sel = (h >= lo) & (h < (hi if hi is not None else np.inf))
        per_bin[_bin_label(lo, hi)] = {"n": int(sel.sum()),
                                        "recall": float(hit[sel].mean()) if sel.any() else None}
    per_tod = {}
    for tod in dict.fromkeys(times):
        sel = np.asarray([t == tod for t in tods], bool)
        per_tod[tod] = {"n": int(sel.sum()), "recall": float(hit[sel].mean()) if sel.any() else None}
    return {
        "recall": float(hit.mean()) if hit.size else None,
        "precision": n_tp / (n_tp + n_fp) if n_tp + n_fp else None,
        "n_pedestrians": int(hit.size),
        "n_detected": n_tp,
        "n_detections": n_det,
        "n_false_positives": n_fp,
        "n_ignored_detections": n_ign,
        "n_frames": n_frames,
        "recall_by_height_px": per_bin,
        "recall_by_time_of_day": per_tod,
        "runtime_s": round(time.perf_counter() - t_start, 2),
        "settings": {
            "n_scenes": n_scenes, "seed": seed, "width": width, "height": height,
            "min_height_px": min_height_px, "min_visible": min_visible, "times": list(times),
            "frames_per_camera": frames_per_camera, "frame_spacing_s": frame_spacing_s,
            "n_pedestrians_per_scene": n_pedestrians, "detector": "cv2 HOG default people detector",
            "hit_threshold": hit_threshold, "scale": scale, "win_stride_px": win_stride_px,
            "padding_px": padding_px, "detect_resolution": "full", "box_shrink_per_side": [SHRINK_W, SHRINK_H],
            "iou_min": IOU_MIN,
        },
    }
