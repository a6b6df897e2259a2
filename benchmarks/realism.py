"""Do the rendered walkers look like people? Recall and precision of detectors trained on real photographs.

Renders global-shutter frames of seeded street scenes from every camera at a few instants, keeps the
pedestrians a detector can fairly be asked to find (box >= ``min_height_px`` tall at full resolution, not cut by
the image border, at least ``min_visible`` of their pixels unoccluded) and runs each detector (any
``load_detector`` spec; by default the shipped SSDLite-MobileNetV2 on 3x2 tiles and OpenCV's stock HOG) on the
same full-resolution frames. Detections are matched greedily (highest score first) one-to-one to the kept
pedestrians at IoU >= 0.5.

Precision counts a detection as false when it matches no kept pedestrian and does not lie mostly (at least half
of its own area) inside one of the pedestrians left out of the evaluation (too small, truncated or occluded):
those are neither credited nor charged, the rule for "ignore" boxes of the Caltech pedestrian benchmark (Dollar
et al., PAMI 2012), where a detection of part of a small or occluded person is not a false alarm. Greedy
matching in score order makes the matches at a higher threshold a prefix of those at a lower one, so one run
gives the whole precision/recall curve: each detector is reported at its own default threshold and at the best recall it
reaches with precision >= ``PRECISION_FLOOR`` (the issue's operating point).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.host.detectors import load_detector
from rollcam.host.detectors.ops import ioa_matrix, iou_matrix
from rollcam.sim.codecs import encode_image
from rollcam.sim.optics import LensOptics
from rollcam.sim.picture import PictureSteps
from rollcam.sim.render.renderer import Renderer, encode_linear
from rollcam.sim.scenegen import DAYLIGHT, TIMES_OF_DAY, make_street_scene

HEIGHT_BINS_PX = (128, 160, 200, 256, 384)
"""Lower edges of the per-height-bin recall (the last bin is open-ended)."""

IOU_MIN = 0.5
PRECISION_FLOOR = 0.8
"""The operating point the realism targets are read at: the best recall with at least this precision."""
DETECTORS = ("ssdlite?tiles=3x2&conf=0.05", "hog")
"""Default detectors: ssdlite at a low threshold, so its curve reaches below its default operating point (its NMS
keeps a box whatever lower-scored boxes exist, so lowering the threshold only adds boxes); hog at its own."""
DEFAULT_THRESHOLDS = {"ssdlite": 0.3, "hog": 0.0}
"""The detectors' own default thresholds (``conf`` of ssdlite, ``hit`` of hog), reported beside the curve."""

Box = tuple[float, float, float, float]


def iou(a: Box, b: Box) -> float:
    """Intersection over union of two (x0, y0, x1, y1) boxes (rollcam.host.detectors.ops.iou_matrix)."""
    return float(iou_matrix([a], [b])[0, 0])


def inside_fraction(a: Box, b: Box) -> float:
    """The fraction of box ``a``'s area that lies inside box ``b`` (Caltech's overlap with an ignore region)."""
    return float(ioa_matrix([a], [b])[0, 0])


def match_frame(dets: Sequence[tuple[Box, float]], kept: Sequence[Box],
                ignored: Sequence[Box]) -> tuple[list[int], list[str]]:
    """Greedy one-to-one matching of detections, taken in score order, to the kept boxes at IoU >= 0.5.

    Returns, per kept box, the index of the detection that found it (-1: missed), and per detection its
    outcome: ``"tp"``, ``"fp"`` or ``"ignored"`` (it only overlaps a box left out of the evaluation).
    """
    found = [-1] * len(kept)
    outcome = [""] * len(dets)
    for d in sorted(range(len(dets)), key=lambda i: -dets[i][1]):
        box = dets[d][0]
        best, best_iou = -1, IOU_MIN
        for g, gt in enumerate(kept):
            if found[g] < 0:
                v = iou(box, gt)
                if v >= best_iou:
                    best, best_iou = g, v
        if best >= 0:
            found[best] = d
            outcome[d] = "tp"
        elif any(inside_fraction(box, gt) >= IOU_MIN for gt in ignored):
            outcome[d] = "ignored"
        else:
            outcome[d] = "fp"
    return found, outcome


def _bin_label(lo: int, hi: int | None) -> str:
    return f"{lo}-{hi}" if hi is not None else f"{lo}+"


@dataclass
class _Tally:
    """One detector's outcomes over the run: per kept walker the score that found it (NaN: missed), per
    detection its score and whether it was a true or false positive (ignored ones dropped)."""

    found_score: list[float] = field(default_factory=list)
    det_score: list[float] = field(default_factory=list)
    det_tp: list[bool] = field(default_factory=list)
    seconds: float = 0.0

    def add(self, dets: Sequence[tuple[Box, float]], kept: Sequence[Box], ignored: Sequence[Box]) -> None:
        found, outcome = match_frame(dets, kept, ignored)
        self.found_score.extend(dets[d][1] if d >= 0 else float("nan") for d in found)
        for (_box, score), what in zip(dets, outcome, strict=True):
            if what != "ignored":
                self.det_score.append(score)
                self.det_tp.append(what == "tp")


def _operating_point(tally: _Tally, threshold: float) -> dict:
    found = np.asarray(tally.found_score)
    hit = found >= threshold  # NaN (missed) compares False
    scores, tp = np.asarray(tally.det_score), np.asarray(tally.det_tp, bool)
    sel = scores >= threshold
    n_tp, n_fp = int((sel & tp).sum()), int((sel & ~tp).sum())
    return {"threshold": float(threshold), "recall": float(hit.mean()) if hit.size else None,
            "precision": n_tp / (n_tp + n_fp) if n_tp + n_fp else None, "n_detected": int(hit.sum()),
            "n_false_positives": n_fp}


def _best_recall_at_precision(tally: _Tally, floor: float) -> dict | None:
    """The operating point of highest recall whose precision is at least ``floor`` (None: none reaches it)."""
    scores, tp = np.asarray(tally.det_score), np.asarray(tally.det_tp, bool)
    if not scores.size or not tally.found_score:
        return None
    order = np.argsort(-scores, kind="stable")
    c_tp, c_fp = np.cumsum(tp[order]), np.cumsum(~tp[order])
    ok = c_tp / (c_tp + c_fp) >= floor
    if not ok.any():
        return None
    k = int(np.flatnonzero(ok)[-1])
    return _operating_point(tally, float(scores[order][k]))


def _recall_table(found_score: np.ndarray, threshold: float, heights: np.ndarray, tods: np.ndarray,
                  times: Sequence[str]) -> tuple[dict, dict]:
    """Recall at ``threshold`` by height band and by time of day."""
    found = found_score >= threshold
    per_bin = {}
    for j, lo in enumerate(HEIGHT_BINS_PX):
        hi = HEIGHT_BINS_PX[j + 1] if j + 1 < len(HEIGHT_BINS_PX) else None
        sel = (heights >= lo) & (heights < (hi if hi is not None else np.inf))
        per_bin[_bin_label(lo, hi)] = {"n": int(sel.sum()), "recall": float(found[sel].mean()) if sel.any() else None}
    per_tod = {}
    for tod in dict.fromkeys(times):
        sel = tods == tod
        per_tod[tod] = {"n": int(sel.sum()), "recall": float(found[sel].mean()) if sel.any() else None}
    return per_bin, per_tod


def _detector_report(spec: str, tally: _Tally, heights: np.ndarray, tods: list[str], times: Sequence[str],
                     floor: float) -> dict:
    name = spec.split("?")[0].split(":")[0]
    default = _operating_point(tally, DEFAULT_THRESHOLDS.get(name, -np.inf))
    best = _best_recall_at_precision(tally, floor)
    key = f"at_precision_{floor:g}"
    found, tod_arr = np.asarray(tally.found_score), np.asarray(tods)
    by_height, by_tod = {}, {}
    for label, point in (("at_default", default), (key, best)):
        if point is not None:
            by_height[label], by_tod[label] = _recall_table(found, point["threshold"], heights, tod_arr, times)
    return {"spec": spec, "at_default": default, key: best, "recall_by_height_px": by_height,
            "recall_by_time_of_day": by_tod, "n_detections": len(tally.det_score), "seconds_per_frame": None}


def realism(
    detectors: Sequence[str] = DETECTORS,
    n_scenes: int = 10,
    seed: int = 0,
    width: int = 1920,
    height: int = 1080,
    min_height_px: float = 128,
    min_visible: float = 0.95,
    times: Sequence[str] = DAYLIGHT,
    frames_per_camera: int = 2,
    progress: Callable[[int, int], None] | None = None,
    *,
    n_pedestrians: int = 30,
    frame_spacing_s: float = 4.0,
    precision_floor: float = PRECISION_FLOOR,
    lens: LensOptics | None = None,
    picture: PictureSteps | None = None,
    shadows: bool = True,
) -> dict:
    """Each detector's recall and precision on unoccluded, untruncated pedestrians of seeded street scenes.

    Scene ``i`` uses seed ``seed + i`` and time of day ``times[i % len(times)]``; every camera of it is rendered
    global-shutter at ``frames_per_camera`` instants ``frame_spacing_s`` apart, and every detector runs on the
    same full-resolution frames, through the camera's ``lens`` and ISP ``picture`` steps when given
    (``rollcam.sim.optics``, ``rollcam.sim.isp``), with the walkers' shadows when ``shadows`` (the default).
    ``progress(done, total)`` is called after each frame. Returns a
    JSON-able dict.
    """
    lens = lens if lens is not None and lens.on else None
    picture = picture if picture is not None and picture.on else None
    if n_scenes < 1 or frames_per_camera < 1 or not times or not detectors:
        raise ConfigError(f"need n_scenes >= 1, frames_per_camera >= 1, some times of day and detectors, got "
                          f"{n_scenes!r}, {frames_per_camera!r}, {times!r}, {detectors!r}")
    dets_by_spec = {spec: load_detector(spec) for spec in detectors}
    tallies = {spec: _Tally() for spec in detectors}
    t_start = time.perf_counter()
    heights: list[float] = []
    tods: list[str] = []
    n_frames = 0
    total = None
    for i in range(n_scenes):
        tod = times[i % len(times)]
        scene = make_street_scene(seed + i, time_of_day=tod, n_pedestrians=n_pedestrians, width=width,
                                  height=height, shadows=shadows)
        if total is None:
            total = n_scenes * len(scene.cameras) * frames_per_camera
        for cam in range(len(scene.cameras)):
            renderer = Renderer(scene, cam)
            for k in range(frames_per_camera):
                t_ns = int((1.0 + k * frame_spacing_s) * 1e9)
                res = renderer.render_lines(np.full(height, t_ns, np.int64), linear=lens is not None)
                kept, ignored = fair_walkers(res, renderer.actor_classes, width, height, min_height_px, min_visible)
                image = res.image if lens is None else encode_linear(lens.apply(res.linear), renderer.gain)
                image = image if picture is None else picture.apply(image)
                heights.extend(b[3] - b[1] for b in kept)
                tods.extend([tod] * len(kept))
                for spec, det in dets_by_spec.items():
                    t0 = time.perf_counter()
                    found = det.detect(image)
                    tallies[spec].seconds += time.perf_counter() - t0
                    tallies[spec].add([(tuple(map(float, b)), float(s)) for b, s in
                                       zip(found.boxes, found.scores, strict=True)], kept, ignored)
                n_frames += 1
                if progress is not None:
                    progress(n_frames, total)
    h = np.asarray(heights)
    reports = {}
    for spec in detectors:
        rep = _detector_report(spec, tallies[spec], h, tods, times, precision_floor)
        rep["seconds_per_frame"] = round(tallies[spec].seconds / max(n_frames, 1), 3)
        reports[spec] = rep
    return {
        "detectors": reports,
        "n_pedestrians": int(h.size),
        "n_frames": n_frames,
        "runtime_s": round(time.perf_counter() - t_start, 2),
        "settings": {
            "n_scenes": n_scenes, "seed": seed, "width": width, "height": height,
            "min_height_px": min_height_px, "min_visible": min_visible, "times": list(times),
            "frames_per_camera": frames_per_camera, "frame_spacing_s": frame_spacing_s,
            "n_pedestrians_per_scene": n_pedestrians, "detect_resolution": "full", "iou_min": IOU_MIN,
            "precision_floor": precision_floor, "shutter": "global", "shadows": shadows,
            "lens": {} if lens is None else lens.info(), "picture": {} if picture is None else picture.info(),
        },
    }


def fair_walkers(res, classes: Sequence[str], width: int, height: int, min_height_px: float,
                 min_visible: float) -> tuple[list[Box], list[Box]]:
    """The GS boxes of a render's pedestrians a detector can fairly be asked to find, and those left out."""
    vis = res.truth.visible_fraction()
    kept: list[Box] = []
    ignored: list[Box] = []
    for o, box in enumerate(res.truth.boxes()):
        if box is None or classes[o] != "person":
            continue
        x0, y0, x1, y1 = box
        inside = x0 >= 1.0 and y0 >= 1.0 and x1 <= width - 1.0 and y1 <= height - 1.0
        if inside and y1 - y0 >= min_height_px and vis[o] >= min_visible:
            kept.append(box)
        else:
            ignored.append(box)
    return kept, ignored


def format_realism(doc: dict) -> str:
    """The study's plain-text report: each detector's recall and precision, by height band and time of day."""
    floor = doc["settings"]["precision_floor"]
    key = f"at_precision_{floor:g}"
    lines = [f"{doc['n_pedestrians']} unoccluded pedestrians >= {doc['settings']['min_height_px']:g} px in "
             f"{doc['n_frames']} GS frames ({', '.join(doc['settings']['times'])})"]
    for spec, rep in doc["detectors"].items():
        a, b = rep["at_default"], rep[key]
        p = "n/a" if a["precision"] is None else f"{a['precision']:.3f}"
        best = "none" if b is None else f"{b['recall']:.3f} (threshold {b['threshold']:.3f})"
        lines.append(f"{spec}: recall {a['recall']:.3f} at precision {p} (threshold {a['threshold']:g}); "
                     f"best recall at precision >= {floor:g}: {best}; {rep['seconds_per_frame']:.2f} s/frame")
        for title, table in (("px", rep["recall_by_height_px"]), ("", rep["recall_by_time_of_day"])):
            row = table.get(key) or table["at_default"]
            cells = [f"{name}{title and ' ' + title}: {r['recall']:.2f} (n={r['n']})" for name, r in row.items()
                     if r["recall"] is not None]
            lines.append("  " + "; ".join(cells))
    return "\n".join(lines)


def write_gallery(folder: str | Path, *, seed: int = 0, times: Sequence[str] = tuple(TIMES_OF_DAY),
                  cameras: Sequence[int] = (0, 1, 2, 3), tile: tuple[int, int] = (640, 360)) -> list[Path]:
    """A contact sheet per time of day (``realism_<time>.jpg``): the street of ``seed`` from ``cameras``, GS.

    Each sheet is 2 x 2 frames rendered at full 1920x1080 and shrunk to ``tile``, what the docs' gallery shows.
    """
    import cv2
    from rollcam.common.files import write_atomic

    out_dir = Path(folder)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for tod in times:
        scene = make_street_scene(seed, time_of_day=tod)
        tiles = []
        for cam in cameras:
            res = Renderer(scene, cam).render_lines(np.full(1080, int(1e9), np.int64))
            tiles.append(cv2.resize(res.image, tile, interpolation=cv2.INTER_AREA))
        while len(tiles) % 2:
            tiles.append(np.zeros_like(tiles[0]))
        sheet = np.vstack([np.hstack(tiles[i:i + 2]) for i in range(0, len(tiles), 2)])
        path = out_dir / f"realism_{tod}.jpg"
        write_atomic(path, encode_image(sheet, "jpg", (cv2.IMWRITE_JPEG_QUALITY, 85), what=f"the {tod} contact sheet"))
        written.append(path)
    return written
