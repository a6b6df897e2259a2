"""Rendering one planned sample into its files (two images, two YOLO label files) and its record.

A record is the sample's commit marker: ``records/<speed>/<name>.json`` is written (atomically, durably) only
after every file of the sample is durably in place, so a sample without a record is incomplete and is redone
on resume. It holds the size and SHA-256 of each of the sample's files (``files``), so a resume also redoes a
sample whose files were cut short or changed behind its record (a power cut, a damaged disk), and the full
ground truth of both images, from which the COCO files and the dataset card are built.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rollcam.common.errors import SourceError
from rollcam.common.files import file_digest, file_matches, write_atomic
from rollcam.sim.frame import Frame

from ..correction.gyro import imu_record
from ..recording.imagefiles import encode_image
from ..sources import open_camera
from .plan import DatasetConfig, LabelPolicy, Sample, Task, speed_tag, subset_name

RECORDS = "records"
CLASS_NAMES = ("person",)
"""YOLO class index -> name (COCO category id is index + 1)."""


@dataclass
class SampleResult:
    """A rendered sample: its record, and the bytes of its files unless a worker already wrote them."""

    key: tuple[str, str]
    record: dict[str, Any]
    files: dict[str, bytes] = field(default_factory=dict)


def _r(v: float) -> float:
    return round(float(v), 3)


def image_labels(frame: Frame, shutter: str, policy: LabelPolicy) -> list[dict[str, Any]]:
    """Objects of one image with the box of its own shutter (GS: ``box_gs``, RS: ``box_rs``) and what the
    label policy makes of them, ordered by object id."""
    out = []
    for o in sorted(frame.objects or (), key=lambda o: o.id):
        if o.cls not in CLASS_NAMES:
            continue
        box = o.box_gs if shutter == "gs" else o.box_rs
        kind = policy.classify(box, o.visible)
        if kind is None:
            continue
        out.append({"id": o.id, "class": o.cls, "box": [_r(v) for v in box], "visible": round(float(o.visible), 4),
                    "speed_mps": round(float(o.speed_mps), 4), "ignore": kind == "ignore"})
    return out


def yolo_text(labels: list[dict[str, Any]], width: int, height: int) -> str:
    """Ultralytics label lines ``class cx cy w h`` (normalised, 6 decimals) for the labelled objects."""
    lines = []
    for lab in labels:
        if lab["ignore"]:
            continue
        x0, y0, x1, y1 = lab["box"]
        lines.append(f"{CLASS_NAMES.index(lab['class'])} {(x0 + x1) / 2 / width:.6f} {(y0 + y1) / 2 / height:.6f} "
                     f"{(x1 - x0) / width:.6f} {(y1 - y0) / height:.6f}")
    return "".join(line + "\n" for line in lines)


def _line_span(frame: Frame) -> list[int] | None:
    """Sample times of the first and last image line (the rest are linear between)."""
    t = frame.row_times_ns
    return None if t is None or not len(t) else [int(t[0]), int(t[-1])]


def image_relpath(s: Sample, shutter: str, ext: str) -> str:
    """Path of a sample's image, relative to the dataset root."""
    return f"{subset_name(s.speed, shutter)}/images/{s.split}/{s.name}.{ext}"


def label_relpath(s: Sample, shutter: str) -> str:
    """Path of a sample's YOLO label file, relative to the dataset root."""
    return f"{subset_name(s.speed, shutter)}/labels/{s.split}/{s.name}.txt"


def record_relpath(key: tuple[str, str]) -> str:
    """Path of a sample's record (its commit marker), relative to the dataset root."""
    return f"{RECORDS}/{key[0]}/{key[1]}.json"


def render_sample(cfg: DatasetConfig, s: Sample) -> SampleResult:
    """Render the GS/RS pair of one sample and build its files and record (nothing is written)."""
    uri = cfg.sample_uri(s)
    with open_camera(uri) as source:
        pair = source.read_pair()
        # the RS frame's IMU over its lines: rollcam eval --correct gyro corrects the stored RS image
        imu = None if pair is None or pair[1].imu is None else imu_record(pair[1], source.device)
    if pair is None:
        raise SourceError(f"source {uri!r} gave no frame")
    files: dict[str, bytes] = {}
    images: dict[str, Any] = {}
    for shutter, frame in zip(("gs", "rs"), pair, strict=True):
        labels = image_labels(frame, shutter, cfg.policy)
        files[image_relpath(s, shutter, cfg.image_format)] = encode_image(frame, cfg.image_format)
        files[label_relpath(s, shutter)] = yolo_text(labels, frame.width, frame.height).encode()
        images[shutter] = {"file": image_relpath(s, shutter, cfg.image_format), "width": frame.width,
                           "height": frame.height, "timestamp_ns": int(frame.timestamp_ns),
                           "line_time_ns": int(frame.line_time_ns), "exposure_ns": int(frame.exposure_ns),
                           "format": frame.format, "readout": frame.readout.value,
                           "line_times_ns": _line_span(frame), "objects": labels}
    record = {"name": s.name, "speed": s.speed, "speed_tag": speed_tag(s.speed), "split": s.split,
              "scene": s.scene, "scene_seed": s.scene_seed, "time_of_day": s.time, "camera": s.camera,
              "start_ns": s.start_ns, "uri": uri, "images": images,
              "files": {rel: file_digest(data) for rel, data in sorted(files.items())}}
    if imu is not None:
        record["imu"] = imu
    return SampleResult(s.key, record, files)


def write_files(root: Path, files: dict[str, bytes]) -> None:
    """Write a sample's files atomically (each via a temporary name and rename)."""
    for rel, data in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, data)


def commit_record(root: Path, result: SampleResult) -> None:
    """Write the record last: from now on the sample counts as done."""
    path = root / record_relpath(result.key)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, (json.dumps(result.record, sort_keys=True) + "\n").encode())


def run_task(cfg: DatasetConfig, task: Task, root: str | None = None,
             skip: frozenset[tuple[str, str]] = frozenset()) -> list[SampleResult]:
    """Render every sample of ``task`` not in ``skip``. With ``root`` (storage the worker shares with the
    driver) the worker writes the files itself and returns records only; without, it returns the bytes."""
    out = []
    for s in task.samples:
        if s.key in skip:
            continue
        result = render_sample(cfg, s)
        if root is not None:
            write_files(Path(root), result.files)
            result.files = {}
        out.append(result)
    return out


def read_records(root: Path) -> dict[tuple[str, str], dict[str, Any]]:
    """Every committed record under ``root``; unreadable ones (never produced by a rename) are skipped."""
    records = {}
    base = root / RECORDS
    if not base.is_dir():
        return records
    for tag_dir in sorted(p for p in base.iterdir() if p.is_dir()):
        for path in sorted(tag_dir.glob("*.json")):
            rec = _read_json(path)
            if rec is not None:
                records[(tag_dir.name, path.stem)] = rec
    return records


def files_intact(root: Path, record: dict[str, Any]) -> bool:
    """Whether every file a record lists is there with its recorded size and SHA-256 (a record from before
    records carried checksums cannot be checked, and counts as not intact)."""
    files = record.get("files")
    if not isinstance(files, dict) or not files:
        return False
    return all(isinstance(d, dict) and file_matches(root / rel, d) for rel, d in files.items())


def _read_json(path: Path) -> dict[str, Any] | None:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def remove_partials(root: Path) -> int:
    """Delete temporary ``*.part`` files a killed run left behind; returns how many."""
    n = 0
    for dirpath, _dirs, names in os.walk(root):
        for name in names:
            if name.endswith(".part"):
                Path(dirpath, name).unlink(missing_ok=True)
                n += 1
    return n
