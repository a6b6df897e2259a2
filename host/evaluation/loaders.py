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
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from rollcam.common.errors import ConfigError
from rollcam.sim.label_formats import check_box, yolo_box, yolo_lines

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


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _coco_set(name: str, doc: Any, image_root: Path, key_prefix: str, where: str, **kw: Any) -> EvalSet:
    """The set a COCO document (from the file ``where``) describes; anything malformed, non-finite boxes and
    negative sizes included, is one ConfigError naming the file and the image, category or annotation."""
    if not isinstance(doc, dict) or not all(isinstance(doc.get(k, []), list)
                                            for k in ("images", "annotations", "categories")):
        raise ConfigError(f"{where!r}: not a COCO file (needs 'images', 'annotations' and 'categories' lists)")
    for i, c in enumerate(doc.get("categories", [])):
        if not isinstance(c, dict) or not isinstance(c.get("id"), int) or not isinstance(c.get("name"), str):
            raise ConfigError(f"{where!r} category {i}: needs an integer 'id' and a 'name', got {str(c)[:80]!r}")
    sizes: dict[Any, tuple[int, int] | None] = {}
    for i, img in enumerate(doc.get("images", [])):
        if not isinstance(img, dict) or "id" not in img or not isinstance(img.get("file_name"), str):
            raise ConfigError(f"{where!r} image {i}: needs an 'id' and a 'file_name', got {str(img)[:80]!r}")
        w, h = img.get("width", 0), img.get("height", 0)
        if not (isinstance(w, int) and isinstance(h, int) and w >= 0 and h >= 0):
            raise ConfigError(f"{where!r} image {i}: width and height must be integers >= 0, got {w!r}x{h!r}")
        sizes[img["id"]] = (w, h) if w and h else None
    cats = sorted(doc.get("categories", []), key=lambda c: c["id"])
    cat_index = {c["id"]: i for i, c in enumerate(cats)}
    per_image: dict[Any, list[tuple[list[float], int, bool]]] = {}
    for i, a in enumerate(doc.get("annotations", [])):
        at = f"{where!r} annotation {i}" + (f" (id {a.get('id')!r})" if isinstance(a, dict) and "id" in a else "")
        if not isinstance(a, dict) or a.get("image_id") not in sizes:
            raise ConfigError(f"{at}: image_id {a.get('image_id') if isinstance(a, dict) else a!r} names no image")
        bbox = a.get("bbox")
        if not (isinstance(bbox, list) and len(bbox) == 4 and all(_number(v) for v in bbox)):
            raise ConfigError(f"{at}: bbox must be [x, y, w, h], got {bbox!r}")
        box = check_box(*(float(v) for v in bbox), sizes[a["image_id"]], f"{at} bbox")
        if a.get("category_id") in cat_index:
            crowd = bool(a.get("iscrowd", 0) or a.get("ignore", 0))
            per_image.setdefault(a["image_id"], []).append((box, cat_index[a["category_id"]], crowd))
    entries = []
    for img in doc.get("images", []):
        anns = per_image.get(img["id"], [])
        truth = Truth.of([b for b, _, _ in anns], [c for _, c, _ in anns], [g for _, _, g in anns],
                         img.get("width", 0), img.get("height", 0))
        entries.append(ImageEntry(key_prefix + img["file_name"], image_root / img["file_name"], img["id"], truth))
    return EvalSet(name, entries, [c["name"] for c in cats], **kw)


def _read_json(path: Path) -> Any:
    """A JSON file, or one ConfigError naming it and where its text breaks."""
    try:
        return json.loads(path.read_text())
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{str(path)!r}: not JSON text ({exc.reason})") from None
    except json.JSONDecodeError as exc:
        raise ConfigError(f"{str(path)!r}: malformed JSON ({exc.msg} at line {exc.lineno} column {exc.colno})"
                          ) from None


def load_rollcam(root: Path, split: str) -> list[EvalSet]:
    """Every subset (speed x shutter) of a rollcam dataset at ``split``."""
    card = json.loads((root / "dataset.json").read_text())
    sets = []
    for name, sub in card["subsets"].items():
        coco = root / sub["coco"].get(split, "")
        if split not in sub["coco"] or not coco.is_file():
            raise ConfigError(f"dataset {str(root)!r} has no {split!r} split for {name!r} "
                              f"(known: {sorted(sub['coco'])})")
        sets.append(_coco_set(name, _read_json(coco), root / name, f"{name}/", str(coco), speed=sub["speed"],
                              shutter=sub["shutter"]))
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
        try:
            with Image.open(p) as im:  # the header only
                w, h = im.size
        except (OSError, SyntaxError, ValueError, Image.DecompressionBombError) as exc:
            raise ConfigError(f"{str(p)!r}: cannot read the image's header ({exc})") from None
        classes, boxes = _yolo_rows(label, (w, h)) if label.is_file() else ([], [])
        entries.append(ImageEntry(str(Path(data[split]) / rel), p, i, Truth.of(boxes, classes, None, w, h)))
    return EvalSet(yaml_path.parent.name or "dataset", entries, class_names)


def _yolo_rows(label: Path, size: tuple[int, int]) -> tuple[list[int], list[list[float]]]:
    """Classes and pixel boxes of an Ultralytics label file (``class cx cy w h`` per line, normalised); a line
    that is not that (non-finite values, negative sizes, a class that is not an integer >= 0 included) is one
    ConfigError naming the file and the line."""
    classes, boxes = [], []
    for at, vals, line in yolo_lines(label, ConfigError):
        if len(vals) < 5:
            raise ConfigError(f"{at}: need 'class cx cy w h', got {len(vals)} values")
        c = vals[0]
        if not math.isfinite(c) or c != int(c) or c < 0:
            raise ConfigError(f"{at}: class must be an integer >= 0, got {line.split()[0]!r}")
        classes.append(int(c))
        boxes.append(yolo_box(vals[1:5], size, at))
    return classes, boxes


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
        doc = _read_json(path)
        if not isinstance(doc, dict) or "images" not in doc:
            raise ConfigError(f"{str(path)!r} is not a COCO dataset file (no 'images')")
        # COCO's own layout keeps annotations/ beside the image folders, and file names relative to their parent.
        default_root = path.parent.parent if path.parent.name == "annotations" else path.parent
        return [_coco_set(path.stem, doc, Path(images) if images else default_root, "", str(path))]
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


def _dets_from_items(items: Any, names: dict[str, int], at: str) -> Dets:
    """One image's detections of a ``detections.jsonl`` line (``at`` names it); a malformed or non-finite one is
    a ConfigError naming the line."""
    if not isinstance(items, list):
        raise ConfigError(f"{at}: 'detections' must be a list, got {str(items)[:80]!r}")
    boxes, scores, classes = [], [], []
    for d in items:
        box, score, cls = (d.get("box"), d.get("score"), d.get("cls", 0)) if isinstance(d, dict) else (None,) * 3
        if not (isinstance(box, list) and len(box) == 4 and all(_number(v) and math.isfinite(v) for v in box)
                and _number(score) and math.isfinite(score) and isinstance(cls, int)):
            raise ConfigError(f"{at}: a detection is {{'box': [x0, y0, x1, y1], 'score': S, 'cls': C}} of finite "
                              f"numbers, got {str(d)[:80]!r}")
        c = names.get(str(d["class"]).lower()) if "class" in d else (cls if 0 <= cls < len(names) else None)
        if c is not None:
            boxes.append(box)
            scores.append(score)
            classes.append(c)
    return Dets.of(boxes, scores, classes)


def load_detections(path: str | Path, sets: list[EvalSet]) -> list[list[Dets]]:
    """Detections from a file, one list per set aligned with its images (images absent from the file: none)."""
    p = Path(path)
    per_set: list[dict[int, Dets]] = [{} for _ in sets]
    if p.suffix == ".json":
        if len(sets) != 1:
            raise ConfigError(f"a COCO results file ({str(p)!r}) has image ids of one set; this dataset has "
                              f"{len(sets)} ({[s.name for s in sets]}): use --subset or a detections.jsonl")
        s = sets[0]
        cat_of = {i + 1: i for i in range(len(s.class_names))}
        ids = {e.image_id: k for k, e in enumerate(s.images)}
        grouped: dict[int, list[dict[str, Any]]] = {}
        results = _read_json(p)
        for i, r in enumerate(results if isinstance(results, list) else [results]):
            bbox, score = (r.get("bbox"), r.get("score")) if isinstance(r, dict) else (None, None)
            if not (isinstance(bbox, list) and len(bbox) == 4 and all(_number(v) for v in bbox) and _number(score)
                    and math.isfinite(score) and "image_id" in r and "category_id" in r):
                raise ConfigError(f"{str(p)!r} result {i}: expected {{'image_id', 'category_id', 'bbox': [x, y, w, h], "
                                  f"'score'}} of finite numbers, got {str(r)[:80]!r}")
            check_box(*(float(v) for v in bbox), None, f"{str(p)!r} result {i} bbox")
            if r["image_id"] in ids and r["category_id"] in cat_of:
                grouped.setdefault(ids[r["image_id"]], []).append(r)
        for k, rs in grouped.items():
            xywh = np.array([r["bbox"] for r in rs], dtype=np.float64).reshape(-1, 4)
            per_set[0][k] = Dets.of(np.c_[xywh[:, :2], xywh[:, :2] + xywh[:, 2:]], [r["score"] for r in rs],
                                    [cat_of[r["category_id"]] for r in rs])
    else:
        try:
            text = p.read_text()
        except UnicodeDecodeError as exc:
            raise ConfigError(f"{str(p)!r}: not JSON lines ({exc.reason})") from None
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
                per_set[si][pos[id(e)]] = _dets_from_items(items, names, f"{p!s}:{n}")
    empty = Dets.of(np.zeros((0, 4)), [], [])
    return [[per_set[si].get(k, empty) for k in range(len(s.images))] for si, s in enumerate(sets)]
