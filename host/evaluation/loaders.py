"""Evaluation inputs: a rollcam dataset, an Ultralytics YOLO dataset or a COCO file; and detections, either
from running a detector or from a file (rollcam ``detections.jsonl`` or a COCO results JSON).

``detections.jsonl``: one JSON object per image, ``{"image": PATH, "detections": [{"box": [x0, y0, x1, y1],
"score": S, "cls": C}, ...]}``, PATH relative to the dataset root as ``rollcam eval --save-detections``
writes it (a path relative to the set's folder, or a bare file name when unique, is accepted too); ``cls`` is
the 0-based class index of the dataset's class list (``"class": NAME`` may replace it). A COCO results JSON
is a list of ``{"image_id", "category_id", "bbox": [x, y, w, h], "score"}`` against the COCO file's ids.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from rollcam.common.errors import ConfigError

from .metrics import Dets, Truth

IMAGE_EXTS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")


@dataclass
class ImageEntry:
    """One image to evaluate: its key (path from the dataset root), file, COCO id and truth; ``prepare``, when
    set, turns the image as read into what the detector sees (``rollcam eval --correct``)."""

    key: str
    path: Path
    image_id: int
    truth: Truth
    prepare: Callable[[np.ndarray], np.ndarray] | None = None


@dataclass
class EvalSet:
    """Images of one dataset (one shutter and speed for rollcam datasets) with one class list;
    ``same_images_as`` names a set whose images (and so detections) these are, under other labels."""

    name: str
    images: list[ImageEntry]
    class_names: list[str]
    speed: str | None = None
    shutter: str | None = None
    same_images_as: str | None = None
    by_key: dict[str, ImageEntry] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.by_key = {e.key: e for e in self.images}


def _coco_set(name: str, doc: dict[str, Any], image_root: Path, key_prefix: str, **kw: Any) -> EvalSet:
    cats = sorted(doc.get("categories", []), key=lambda c: c["id"])
    cat_index = {c["id"]: i for i, c in enumerate(cats)}
    per_image: dict[int, list[dict[str, Any]]] = {}
    for a in doc.get("annotations", []):
        per_image.setdefault(a["image_id"], []).append(a)
    entries = []
    for img in doc.get("images", []):
        anns = [a for a in per_image.get(img["id"], []) if a["category_id"] in cat_index]
        boxes = [[a["bbox"][0], a["bbox"][1], a["bbox"][0] + a["bbox"][2], a["bbox"][1] + a["bbox"][3]] for a in anns]
        truth = Truth.of(boxes, [cat_index[a["category_id"]] for a in anns],
                         [bool(a.get("iscrowd", 0) or a.get("ignore", 0)) for a in anns],
                         img.get("width", 0), img.get("height", 0))
        entries.append(ImageEntry(key_prefix + img["file_name"], image_root / img["file_name"], img["id"], truth))
    return EvalSet(name, entries, [c["name"] for c in cats], **kw)


def load_rollcam(root: Path, split: str) -> list[EvalSet]:
    """Every subset (speed x shutter) of a rollcam dataset at ``split``."""
    card = json.loads((root / "dataset.json").read_text())
    sets = []
    for name, sub in card["subsets"].items():
        coco = root / sub["coco"].get(split, "")
        if split not in sub["coco"] or not coco.is_file():
            raise ConfigError(f"dataset {str(root)!r} has no {split!r} split for {name!r} "
                              f"(known: {sorted(sub['coco'])})")
        doc = json.loads(coco.read_text())
        sets.append(_coco_set(name, doc, root / name, f"{name}/", speed=sub["speed"], shutter=sub["shutter"]))
    return sets


def load_yolo(yaml_path: Path, split: str) -> EvalSet:
    """An Ultralytics dataset (``data.yaml``) at ``split``; image sizes are read from the file headers."""
    from PIL import Image

    data = yaml.safe_load(yaml_path.read_text()) or {}
    base = Path(data.get("path") or yaml_path.parent)
    if not base.is_absolute():
        base = yaml_path.parent / base
    if split not in data:
        known = [k for k in data if k in ("train", "val", "test")]
        raise ConfigError(f"{str(yaml_path)!r} names no {split!r} split (has: {known})")
    names = data.get("names", {})
    class_names = [names[i] for i in sorted(names)] if isinstance(names, dict) else list(names)
    img_dir = base / data[split]
    files = sorted(p for p in img_dir.rglob("*") if p.suffix.lower() in IMAGE_EXTS)
    entries = []
    for i, p in enumerate(files, start=1):
        rel = p.relative_to(img_dir)
        # Ultralytics' rule: the label of .../images/x.png is .../labels/x.txt (last "images" in the path).
        label = Path("/labels/".join(str(p.with_suffix(".txt")).rsplit("/images/", 1)))
        with Image.open(p) as im:
            w, h = im.size
        rows = np.loadtxt(label, ndmin=2) if label.is_file() and label.stat().st_size else np.zeros((0, 5))
        c, cx, cy, bw, bh = (rows[:, k] for k in range(5))
        boxes = np.c_[(cx - bw / 2) * w, (cy - bh / 2) * h, (cx + bw / 2) * w, (cy + bh / 2) * h]
        entries.append(ImageEntry(str(Path(data[split]) / rel), p, i, Truth.of(boxes, c.astype(int), None, w, h)))
    return EvalSet(yaml_path.parent.name or "dataset", entries, class_names)


def load_sets(dataset: str | Path, split: str, images: str | Path | None = None) -> list[EvalSet]:
    """What to evaluate: a rollcam dataset folder, a ``data.yaml`` (or a folder holding one), or a COCO JSON."""
    path = Path(dataset)
    if path.is_dir() and (path / "dataset.json").is_file():
        return load_rollcam(path, split)
    if path.is_dir() and (path / "data.yaml").is_file():
        return [load_yolo(path / "data.yaml", split)]
    if path.is_file() and path.suffix in (".yaml", ".yml"):
        return [load_yolo(path, split)]
    if path.is_file() and path.suffix == ".json":
        doc = json.loads(path.read_text())
        if not isinstance(doc, dict) or "images" not in doc:
            raise ConfigError(f"{str(path)!r} is not a COCO dataset file (no 'images')")
        # COCO's own layout keeps annotations/ beside the image folders, and file names relative to their parent.
        default_root = path.parent.parent if path.parent.name == "annotations" else path.parent
        return [_coco_set(path.stem, doc, Path(images) if images else default_root, "")]
    raise ConfigError(f"dataset {str(dataset)!r} is not a rollcam dataset folder, a YOLO data.yaml (or folder with "
                      "one), or a COCO JSON file")


def run_detector(detector: Any, s: EvalSet, on_image: Callable[[], None] | None = None) -> list[Dets]:
    """Detections of ``detector`` on every image of ``s``, classes mapped to the set's by name."""
    import cv2

    names = {n.lower(): i for i, n in enumerate(s.class_names)}
    to_set = {c: names[n.lower()] for c, n in detector.class_names.items() if n.lower() in names}
    # A raw-input detector gets the stored mosaic as it is (8 or 16 bit); others get 8-bit BGR.
    flags = cv2.IMREAD_UNCHANGED if getattr(detector, "input", "bgr") == "raw" else cv2.IMREAD_COLOR
    out = []
    for e in s.images:
        img = cv2.imread(str(e.path), flags)
        if img is None:
            raise ConfigError(f"cannot read image {str(e.path)!r}")
        d = detector.detect(img if e.prepare is None else e.prepare(img))
        keep = np.array([int(c) in to_set for c in d.classes], bool)
        out.append(Dets.of(d.boxes[keep], d.scores[keep], [to_set[int(c)] for c in d.classes[keep]]))
        if on_image is not None:
            on_image()
    return out


def _find(s: EvalSet, image: str, basenames: dict[str, ImageEntry | None]) -> ImageEntry | None:
    if image in s.by_key:
        return s.by_key[image]
    prefix = f"{s.name}/"
    if prefix + image in s.by_key:
        return s.by_key[prefix + image]
    return basenames.get(Path(image).name)


def _dets_from_items(items: list[dict[str, Any]], names: dict[str, int]) -> Dets:
    boxes, scores, classes = [], [], []
    for d in items:
        if "class" in d:
            c = names.get(str(d["class"]).lower())
        else:
            c = int(d.get("cls", 0))
            c = c if 0 <= c < len(names) else None
        if c is not None:
            boxes.append(d["box"])
            scores.append(d["score"])
            classes.append(c)
    return Dets.of(boxes, scores, classes)


def load_detections(path: str | Path, sets: list[EvalSet]) -> list[list[Dets]]:
    """Detections from a file, one list per set aligned with its images (images absent from the file: none)."""
    p = Path(path)
    text = p.read_text()
    per_set: list[dict[int, Dets]] = [{} for _ in sets]
    if p.suffix == ".json":
        if len(sets) != 1:
            raise ConfigError(f"a COCO results file ({str(p)!r}) has image ids of one set; this dataset has "
                              f"{len(sets)} ({[s.name for s in sets]}): use --subset or a detections.jsonl")
        s = sets[0]
        cat_of = {i + 1: i for i in range(len(s.class_names))}
        ids = {e.image_id: k for k, e in enumerate(s.images)}
        grouped: dict[int, list[dict[str, Any]]] = {}
        for r in json.loads(text):
            if r["image_id"] in ids and r["category_id"] in cat_of:
                grouped.setdefault(ids[r["image_id"]], []).append(r)
        for k, rs in grouped.items():
            xywh = np.array([r["bbox"] for r in rs], dtype=np.float64).reshape(-1, 4)
            per_set[0][k] = Dets.of(np.c_[xywh[:, :2], xywh[:, :2] + xywh[:, 2:]], [r["score"] for r in rs],
                                    [cat_of[r["category_id"]] for r in rs])
    else:
        index = []
        for si, s in enumerate(sets):
            names = {n.lower(): i for i, n in enumerate(s.class_names)}
            counts: dict[str, int] = {}
            for e in s.images:
                counts[Path(e.key).name] = counts.get(Path(e.key).name, 0) + 1
            basenames = {Path(e.key).name: e for e in s.images if counts[Path(e.key).name] == 1}
            pos = {id(e): k for k, e in enumerate(s.images)}
            index.append((si, s, names, basenames, pos))
        for n, line in enumerate(text.splitlines(), start=1):
            if not line.strip():
                continue
            try:
                rec = json.loads(line)
                image = rec["image"] if "image" in rec else rec["file"]
                items = rec["detections"]
            except (ValueError, KeyError, TypeError):
                raise ConfigError(f"{p!s}:{n}: expected {{'image': PATH, 'detections': [...]}}") from None
            hits = [(si, names, pos, s.by_key[image]) for si, s, names, _b, pos in index if image in s.by_key]
            if not hits:  # a path relative to a set's folder, or a bare file name: must name one image only
                hits = [(si, names, pos, e) for si, s, names, b, pos in index if (e := _find(s, image, b))]
                if len(hits) > 1:
                    raise ConfigError(f"{p!s}:{n}: image {image!r} matches images of several sets "
                                      f"({[sets[h[0]].name for h in hits]}); give its path from the dataset root")
            for si, names, pos, e in hits:
                per_set[si][pos[id(e)]] = _dets_from_items(items, names)
    empty = Dets.of(np.zeros((0, 4)), [], [])
    return [[per_set[si].get(k, empty) for k in range(len(s.images))] for si, s in enumerate(sets)]
