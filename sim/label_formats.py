"""Readers of per-frame footage labels in common forms, each into a ``LabelTrack`` (``rollcam.sim.footage_labels``).

``load_labels(path, fmt, n_frames=, size=, frame_names=)``; ``fmt`` is ``auto`` or one of ``FORMATS``:

- ``masks``: a folder of instance-mask images, one per footage frame in natural sort order (PNG, 8- or 16-bit
  single channel, or ``.npy``): 0 is background, any other value the id of the instance the pixel shows.
  Optional amodal masks ``amodal/<frame stem>/<id>.png`` (nonzero = covered, hidden or not) give visibility.
- ``coco``: a COCO JSON file: one image per footage frame (matched by file name to a folder footage's frames,
  else by ``frame_index`` or natural order of ``file_name``), annotations with ``bbox`` and a track id
  (``track_id``, ``instance_id`` or ``object_id``), optionally ``segmentation`` (RLE or polygons) on every
  annotation (then the labels are masks) and ``visible`` (a fraction).
- ``mot``: MOT Challenge text, ``frame,id,x,y,w,h[,conf,class,visibility]`` with 1-based frames (class 1 is a
  pedestrian, so ``person``).
- ``yolo``: a folder of Ultralytics label files, ``<frame stem>.txt`` per footage frame, lines
  ``class cx cy w h id`` (or ``class cx cy w h conf id``) normalised to the frame size; class 0 is ``person``.

Every problem is one ``SourceError`` naming the file (and line or annotation) and what is wrong.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from rollcam.common.errors import ConfigError, RollcamError, SourceError

from .footage import natural_key
from .footage_labels import BoxLabels, LabelTrack, MaskLabels

FORMATS = ("masks", "coco", "mot", "yolo")
BOX_REACH = 100  # a box may reach this many footage widths (heights) beyond the frame; further is a broken file
MASK_SUFFIXES = (".png", ".npy", ".tif", ".tiff")
_TRACK_KEYS = ("track_id", "instance_id", "object_id")


def detect_format(path: Path) -> str:
    """The label format a path holds by its shape: a folder of masks or YOLO txt files, a JSON or text file."""
    if path.is_dir():
        names = [p.suffix.lower() for p in path.iterdir() if p.is_file()]
        if any(s in MASK_SUFFIXES for s in names):
            return "masks"
        if ".txt" in names:
            return "yolo"
        raise SourceError(f"{str(path)!r}: label folder holds neither mask images nor YOLO .txt files")
    if path.suffix.lower() == ".json":
        return "coco"
    if path.suffix.lower() in (".txt", ".csv"):
        return "mot"
    raise SourceError(f"{str(path)!r}: cannot tell the label format from the name; pass label_format= "
                      f"(one of {list(FORMATS)})")


def load_labels(path: str | Path, fmt: str = "auto", *, n_frames: int, size: tuple[int, int],
                frame_names: Sequence[str] | None = None) -> LabelTrack:
    """The labels at ``path`` for a footage of ``n_frames`` frames of ``size`` (width, height).

    ``frame_names`` (a folder footage's file names) lets per-frame files be matched to frames by name.
    """
    p = Path(path)
    if not p.exists():
        raise SourceError(f"{str(p)!r}: no such label file or folder")
    if fmt == "auto":
        fmt = detect_format(p)
    if fmt not in FORMATS:
        raise ConfigError(f"label format {fmt!r} is not one of {['auto', *FORMATS]}")
    reader = {"masks": _load_masks, "coco": _load_coco, "mot": _load_mot, "yolo": _load_yolo}[fmt]
    track = reader(p, n_frames, size, frame_names)
    track.check_footage(n_frames, size)
    return track


def check_box(x: float, y: float, w: float, h: float, size: tuple[int, int] | None, at: str) -> list[float]:
    """The box ``x, y, w, h`` (pixels) as ``[x0, y0, x1, y1]``, or one ``SourceError`` at ``at`` when a value is
    not finite, a size is negative or the box reaches more than ``BOX_REACH`` frames beyond the image of ``size``
    (width, height; None when unknown: that check is skipped). Every reader of other people's boxes uses it."""
    vals = (x, y, w, h)
    if not all(math.isfinite(v) for v in vals):
        raise SourceError(f"{at}: box [x, y, w, h] must be finite numbers, got [{', '.join(f'{v:g}' for v in vals)}]")
    if w < 0 or h < 0:
        raise SourceError(f"{at}: box width and height must be >= 0, got {w:g}x{h:g}")
    if size is not None and max(abs(x), abs(y), abs(x + w), abs(y + h)) > BOX_REACH * max(size):
        raise SourceError(f"{at}: box [{', '.join(f'{v:g}' for v in vals)}] reaches more than {BOX_REACH} frames "
                          f"beyond the {size[0]}x{size[1]} image")
    return [x, y, x + w, y + h]


def _per_frame_files(folder: Path, suffixes: Sequence[str], n_frames: int, frame_names: Sequence[str] | None,
                     what: str) -> list[Path]:
    """One file per footage frame: by frame file stem when the footage is a folder, else in natural order."""
    files = sorted((q for q in folder.iterdir() if q.is_file() and q.suffix.lower() in suffixes), key=natural_key)
    if frame_names is not None:
        by_stem = {q.stem: q for q in files}
        stems = [Path(n).stem for n in frame_names]
        missing = [s for s in stems if s not in by_stem]
        if not missing:
            return [by_stem[s] for s in stems]
        if len(missing) < len(stems) or len(files) != n_frames:  # named after the frames, but not all of them
            raise SourceError(f"{str(folder)!r}: no {what} for footage frame {missing[0]!r} "
                              f"({len(missing)} of {n_frames} frames have none)")
    if len(files) != n_frames:
        raise SourceError(f"{str(folder)!r}: holds {len(files)} {what} files, the footage {n_frames} frames")
    return files


# ------------------------------------------------------------------------------------------------ masks
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def mask_header_shape(path: Path) -> tuple[int, ...] | None:
    """The array shape (rows, columns[, ...]) a PNG (its IHDR) or ``.npy`` file (its header) declares, read
    without decoding the data, so a file declaring a huge image is refused before anything is allocated; None
    for other files (their decoder checks them) and a PNG whose first chunk is not IHDR (its decoder refuses it).
    """
    try:
        with path.open("rb") as f:
            if path.suffix.lower() == ".npy":
                version = np.lib.format.read_magic(f)
                read = np.lib.format.read_array_header_1_0 if version == (1, 0) else \
                    np.lib.format.read_array_header_2_0
                shape, _fortran, _dtype = read(f)
                return tuple(int(n) for n in shape)
            head = f.read(33)
    except (OSError, ValueError, TypeError, SyntaxError) as exc:
        raise SourceError(f"{str(path)!r}: cannot read the mask's header ({exc})") from None
    if head[:8] != PNG_SIGNATURE or head[12:16] != b"IHDR":
        return None
    width, height = int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
    return (height, width)


def read_mask(path: Path, size: tuple[int, int]) -> np.ndarray:
    """One instance-mask image as an int64 H x W array of ids (refusing colour, wrong size or undecodable).

    A PNG's or ``.npy``'s declared size is checked against the footage's ``size`` from its header first."""
    declared = mask_header_shape(path)
    if declared is not None and declared[:2] != (size[1], size[0]):
        what = "x".join(map(str, declared[1::-1])) if len(declared) >= 2 else f"of shape {declared!r}"
        raise SourceError(f"{str(path)!r}: mask is {what}, the footage {size[0]}x{size[1]} (from its header)")
    if path.suffix.lower() == ".npy":
        try:
            m = np.load(path, allow_pickle=False)
        except (OSError, ValueError, EOFError) as exc:
            raise SourceError(f"{str(path)!r}: cannot load mask array ({exc})") from None
    else:
        m = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if m is None:
            raise SourceError(f"{str(path)!r}: cannot decode mask image (corrupt or unsupported file)")
    if m.ndim != 2 or not (np.issubdtype(m.dtype, np.integer) or m.dtype == np.bool_):
        raise SourceError(f"{str(path)!r}: an instance mask must be one channel of integer ids (8- or 16-bit), "
                          f"got {m.dtype} of shape {m.shape!r}")
    if (m.shape[1], m.shape[0]) != tuple(size):
        raise SourceError(f"{str(path)!r}: mask is {m.shape[1]}x{m.shape[0]}, the footage {size[0]}x{size[1]}")
    return m.astype(np.int64)


def _load_masks(folder: Path, n_frames: int, size: tuple[int, int], names: Sequence[str] | None) -> LabelTrack:
    if not folder.is_dir():
        raise SourceError(f"{str(folder)!r}: mask labels must be a folder of mask images")
    files = _per_frame_files(folder, MASK_SUFFIXES, n_frames, names, "mask")
    amodal_root = folder / "amodal"

    def load(k: int) -> MaskLabels:
        vis = read_mask(files[k], size)
        frame_dir = amodal_root / files[k].stem
        if not frame_dir.is_dir():
            return MaskLabels(vis)
        amodal = {}
        for q in sorted(frame_dir.iterdir(), key=natural_key):
            if not q.stem.isdigit() or int(q.stem) <= 0:
                raise SourceError(f"{str(q)!r}: amodal mask files are named by instance id (1.png, 2.png, ...)")
            amodal[int(q.stem)] = read_mask(q, size) != 0
        for oid in np.unique(vis[vis != 0]).tolist():
            cover = amodal.get(oid)
            if cover is None:
                raise SourceError(f"{str(files[k])!r}: instance id {oid} shows but has no amodal mask in "
                                  f"{str(frame_dir)!r}")
            if np.any((vis == oid) & ~cover):
                raise SourceError(f"{str(files[k])!r}: instance id {oid} shows outside its amodal mask "
                                  f"{str(frame_dir / f'{oid}.png')!r}")
        return MaskLabels(vis, amodal)

    return LabelTrack(str(folder), n_frames, size, "lines", load)


# ------------------------------------------------------------------------------------------------- COCO
def rle_decode(rle: dict[str, Any], where: str, footage: tuple[int, int] | None = None) -> np.ndarray:
    """A COCO RLE (``{"size": [h, w], "counts": list or compressed string}``) as an H x W bool mask.

    With ``footage`` (width, height) the declared size must be the footage's, checked before the counts are
    read or anything is allocated, so the counts are bounded by the footage's pixels."""
    try:
        h, w = (int(v) for v in rle["size"])
        counts = rle["counts"]
    except (KeyError, TypeError, ValueError):
        raise SourceError(f"{where}: RLE segmentation needs 'size' [h, w] and 'counts'") from None
    if footage is not None and (w, h) != tuple(footage):
        raise SourceError(f"{where}: RLE mask declares {w}x{h}, the footage is {footage[0]}x{footage[1]}")
    if h < 0 or w < 0:
        raise SourceError(f"{where}: RLE size [{h}, {w}] is negative")
    if isinstance(counts, str):
        counts = _rle_string(counts, where)
    if not isinstance(counts, list) or not all(isinstance(c, int) and c >= 0 for c in counts):
        raise SourceError(f"{where}: RLE 'counts' must be non-negative integers or a compressed string")
    if sum(counts) != h * w:
        raise SourceError(f"{where}: RLE counts sum to {sum(counts)}, not h*w = {h * w}")
    flat = np.zeros(h * w, np.bool_)
    pos = np.cumsum([0, *counts])
    for j in range(1, len(counts), 2):  # runs alternate 0s, 1s, ... starting with 0s
        flat[pos[j]:pos[j + 1]] = True
    return flat.reshape(w, h).T  # COCO RLE runs down columns


def _rle_string(s: str, where: str) -> list[int]:
    """COCO's compressed RLE counts (pycocotools ``rleFrString``): 5-bit groups, deltas after the second."""
    counts: list[int] = []
    p = 0
    while p < len(s):
        x, k, more = 0, 0, True
        while more:
            if p >= len(s):
                raise SourceError(f"{where}: compressed RLE counts end inside a number")
            c = ord(s[p]) - 48
            x |= (c & 0x1F) << (5 * k)
            more = bool(c & 0x20)
            p += 1
            k += 1
            if not more and (c & 0x10):
                x |= -1 << (5 * k)
        if len(counts) > 2:
            x += counts[-2]
        counts.append(x)
    return counts


def polygon_mask(pts: np.ndarray, h: int, w: int) -> np.ndarray:
    """Pixels whose centre lies inside the polygon ``pts`` (N x 2, x y; even-odd rule), as an H x W bool mask.

    The same centre rule as instance masks and rollcam's own coverage; pycocotools' rasteriser, which traces an
    upsampled outline, differs from it on a few percent of pixels, all on the outline.
    """
    out = np.zeros((h, w), np.bool_)
    x0, x1 = max(int(np.floor(pts[:, 0].min())), 0), min(int(np.ceil(pts[:, 0].max())) + 1, w)
    y0, y1 = max(int(np.floor(pts[:, 1].min())), 0), min(int(np.ceil(pts[:, 1].max())) + 1, h)
    if x1 <= x0 or y1 <= y0:
        return out
    ys, xs = np.mgrid[y0:y1, x0:x1] + 0.5
    inside = np.zeros(xs.shape, np.bool_)
    for (ax, ay), (bx, by) in zip(pts, np.roll(pts, -1, axis=0), strict=True):
        if ay == by:
            continue  # a horizontal edge crosses no centre line
        crosses = (ay > ys) != (by > ys)
        inside ^= crosses & (xs < ax + (ys - ay) * (bx - ax) / (by - ay))
    out[y0:y1, x0:x1] = inside
    return out


def _coco_mask(seg: Any, size: tuple[int, int], where: str) -> np.ndarray:
    w, h = size
    if isinstance(seg, dict):
        return rle_decode(seg, where, size)
    if isinstance(seg, list) and seg and all(isinstance(poly, list) and len(poly) >= 6 and len(poly) % 2 == 0
                                             for poly in seg):
        out = np.zeros((h, w), np.bool_)
        for poly in seg:
            if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in poly):
                raise SourceError(f"{where}: polygon coordinates must be finite numbers")
            out |= polygon_mask(np.asarray(poly, np.float64).reshape(-1, 2), h, w)
        return out
    raise SourceError(f"{where}: segmentation must be an RLE dict or a list of polygons (x, y, ... >= 3 points)")


def _load_coco(path: Path, n_frames: int, size: tuple[int, int], names: Sequence[str] | None) -> LabelTrack:
    where = str(path)
    try:
        doc = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise SourceError(f"{where!r}: cannot read COCO labels ({exc})") from None
    except json.JSONDecodeError as exc:
        raise SourceError(f"{where!r}: malformed JSON ({exc.msg} at line {exc.lineno} column {exc.colno})") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("images"), list) \
            or not isinstance(doc.get("annotations"), list):
        raise SourceError(f"{where!r}: not a COCO file (needs 'images' and 'annotations' lists)")
    cats = {c.get("id"): str(c.get("name")) for c in doc.get("categories", []) if isinstance(c, dict)}
    frame_of_image = _coco_frames(doc["images"], where, n_frames, names)
    per_frame: list[list[tuple[int, list[float], float, Any]]] = [[] for _ in range(n_frames)]
    classes: dict[int, str] = {}
    with_seg = 0
    for i, a in enumerate(doc["annotations"]):
        at = f"{where!r} annotation {i}" + (f" (id {a.get('id')!r})" if isinstance(a, dict) and "id" in a else "")
        if not isinstance(a, dict) or a.get("image_id") not in frame_of_image:
            raise SourceError(f"{at}: image_id {a.get('image_id') if isinstance(a, dict) else a!r} names no image")
        oid = next((a[k] for k in _TRACK_KEYS if k in a), None)
        if not isinstance(oid, int) or isinstance(oid, bool) or oid <= 0:
            raise SourceError(f"{at}: needs a positive integer track id ({'/'.join(_TRACK_KEYS)}), got {oid!r}")
        bbox = a.get("bbox")
        if not (isinstance(bbox, list) and len(bbox) == 4
                and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in bbox)):
            raise SourceError(f"{at}: bbox must be [x, y, w, h], got {bbox!r}")
        box = check_box(*(float(v) for v in bbox), size, f"{at} bbox")
        vis = a.get("visible", 1.0)
        if not isinstance(vis, (int, float)) or not 0.0 <= vis <= 1.0:  # NaN fails the comparison too
            raise SourceError(f"{at}: visible must be a fraction in [0, 1], got {vis!r}")
        if a.get("category_id") in cats:
            classes[oid] = "person" if cats[a["category_id"]] == "pedestrian" else cats[a["category_id"]]
        with_seg += "segmentation" in a
        per_frame[frame_of_image[a["image_id"]]].append((oid, box, float(vis), a.get("segmentation")))
        if any(o == oid for o, *_ in per_frame[frame_of_image[a["image_id"]]][:-1]):
            raise SourceError(f"{at}: track id {oid} appears twice in image {a['image_id']!r}")
    if with_seg not in (0, len(doc["annotations"])):
        raise SourceError(f"{where!r}: {with_seg} of {len(doc['annotations'])} annotations have a segmentation; "
                          "give every annotation one (mask labels) or none (box labels)")
    if with_seg:
        def load(k: int) -> MaskLabels:
            vis_mask = np.zeros((size[1], size[0]), np.int64)
            amodal = {}
            for oid, _bbox, _vis, seg in per_frame[k]:
                amodal[oid] = _coco_mask(seg, size, f"{where!r} frame {k} track {oid}")
                vis_mask[amodal[oid] & (vis_mask == 0)] = oid  # COCO masks are what shows; overlaps go to the first
            return MaskLabels(vis_mask, amodal)

        return LabelTrack(where, n_frames, size, "lines", load, classes)

    def load_boxes(k: int) -> BoxLabels:
        rows = per_frame[k]
        return BoxLabels.of([r[0] for r in rows], [r[1] for r in rows], [r[2] for r in rows])

    return LabelTrack(where, n_frames, size, "boxes", load_boxes, classes)


def _coco_frames(images: list[Any], where: str, n_frames: int, names: Sequence[str] | None) -> dict[Any, int]:
    """Footage frame index of each COCO image id."""
    for i, img in enumerate(images):
        if not isinstance(img, dict) or "id" not in img or not isinstance(img.get("file_name", ""), str):
            raise SourceError(f"{where!r}: image {i} needs an 'id' and a 'file_name'")
    ids = [img["id"] for img in images]
    if len(set(map(repr, ids))) != len(ids):
        raise SourceError(f"{where!r}: image ids repeat")
    if names is not None:
        index = {Path(n).name: k for k, n in enumerate(names)}
        got = {Path(img.get("file_name", "")).name for img in images}
        if got & set(index):  # named after the frames: every frame needs its image
            missing = [n for n in index if n not in got]
            if missing:
                raise SourceError(f"{where!r}: no image for footage frame {missing[0]!r} ({len(missing)} missing)")
            return {img["id"]: index[Path(img["file_name"]).name] for img in images}
    if len(images) != n_frames:
        raise SourceError(f"{where!r}: holds {len(images)} images, the footage {n_frames} frames")
    if all(isinstance(img.get("frame_index"), int) for img in images):
        order = sorted(images, key=lambda img: img["frame_index"])
    else:
        order = sorted(images, key=lambda img: natural_key(Path(img.get("file_name", ""))))
    return {img["id"]: k for k, img in enumerate(order)}


# -------------------------------------------------------------------------------------------------- MOT
def _load_mot(path: Path, n_frames: int, size: tuple[int, int], names: Sequence[str] | None) -> LabelTrack:
    where = str(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise SourceError(f"{where!r}: cannot read MOT labels ({exc})") from None
    rows: list[list[tuple[int, list[float], float]]] = [[] for _ in range(n_frames)]
    classes: dict[int, str] = {}
    for ln, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        parts = [p.strip() for p in re.split(r"[,\s]+", line.strip())]
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            raise SourceError(f"{where!r} line {ln}: not numbers: {line.strip()!r}") from None
        if len(vals) < 6 or not all(np.isfinite(vals)):
            raise SourceError(f"{where!r} line {ln}: need frame,id,x,y,w,h[,conf,class,visibility], "
                              f"got {line.strip()!r}")
        frame, oid = vals[0], vals[1]
        if frame != int(frame) or not 1 <= frame <= n_frames:
            raise SourceError(f"{where!r} line {ln}: frame {parts[0]!r} is not in 1..{n_frames} (the footage's frames)")
        if oid != int(oid) or oid <= 0:
            raise SourceError(f"{where!r} line {ln}: id {parts[1]!r} must be a positive integer")
        box = check_box(*vals[2:6], size, f"{where!r} line {ln}")
        vis = vals[8] if len(vals) > 8 else 1.0
        if not 0.0 <= vis <= 1.0:
            raise SourceError(f"{where!r} line {ln}: visibility {parts[8]!r} is not in [0, 1]")
        if len(vals) > 7:
            classes[int(oid)] = "person" if vals[7] == 1 else f"class{int(vals[7])}"
        k = int(frame) - 1
        if any(o == int(oid) for o, _, _ in rows[k]):
            raise SourceError(f"{where!r} line {ln}: id {int(oid)} appears twice in frame {int(frame)}")
        rows[k].append((int(oid), box, vis))

    def load(k: int) -> BoxLabels:
        return BoxLabels.of([r[0] for r in rows[k]], [r[1] for r in rows[k]], [r[2] for r in rows[k]])

    return LabelTrack(where, n_frames, size, "boxes", load, classes)


# ------------------------------------------------------------------------------------------------- YOLO
def yolo_lines(path: Path, error: type[RollcamError]) -> Iterator[tuple[str, list[float], str]]:
    """Each non-blank line of an Ultralytics label file as (where, its numbers, the line): the one reader of YOLO
    label lines (footage labels here, evaluation sets in rollcam.host.evaluation.loaders). ``where`` names the
    file and line for the caller's errors; a file that cannot be read, or a line that is not numbers, raises
    ``error`` (the caller's kind: SourceError for footage, ConfigError for a dataset)."""
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{str(path)!r}: cannot read YOLO labels ({exc})") from None
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        at = f"{str(path)!r} line {number}"
        try:
            values = [float(v) for v in line.split()]
        except ValueError:
            raise error(f"{at}: not numbers: {line.strip()[:80]!r}") from None
        yield at, values, line


def yolo_box(cxcywh: Sequence[float], size: tuple[int, int], at: str) -> list[float]:
    """A YOLO line's normalised ``cx cy w h`` as a pixel box ``[x0, y0, x1, y1]`` in an image of ``size``
    (checked by ``check_box``)."""
    cx, cy, bw, bh = cxcywh
    w, h = size
    return check_box((cx - bw / 2) * w, (cy - bh / 2) * h, bw * w, bh * h, size, at)


def _load_yolo(folder: Path, n_frames: int, size: tuple[int, int], names: Sequence[str] | None) -> LabelTrack:
    if not folder.is_dir():
        raise SourceError(f"{str(folder)!r}: YOLO labels must be a folder of .txt files, one per frame")
    files = _per_frame_files(folder, (".txt",), n_frames, names, "label")
    classes: dict[int, str] = {}

    def load(k: int) -> BoxLabels:
        ids, boxes = [], []
        for at, vals, line in yolo_lines(files[k], SourceError):
            if len(vals) not in (6, 7):
                raise SourceError(f"{at}: need 'class cx cy w h id' (or with conf before id) to follow objects "
                                  f"across frames, got {len(vals)} values")
            cls, oid = vals[0], vals[-1]
            if not (math.isfinite(oid) and math.isfinite(cls)) or oid != int(oid) or oid <= 0 or cls != int(cls) \
                    or cls < 0:
                raise SourceError(f"{at}: class and id must be integers (id >= 1), got {line.strip()!r}")
            if int(oid) in ids:
                raise SourceError(f"{at}: id {int(oid)} appears twice")
            box = yolo_box(vals[1:5], size, at)
            classes[int(oid)] = "person" if cls == 0 else f"class{int(cls)}"
            ids.append(int(oid))
            boxes.append(box)
        return BoxLabels.of(ids, boxes)

    return LabelTrack(str(folder), n_frames, size, "boxes", load, classes)
