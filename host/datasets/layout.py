"""The files that describe a finished dataset: COCO JSON per subset and split, Ultralytics ``data.yaml``,
and the dataset card (``dataset.json`` for programs, ``README.md`` for people).

Everything here is built from the sample records in sorted order, so its bytes depend only on the config,
never on how many workers rendered the samples or in which order they finished.
"""

from __future__ import annotations

import hashlib
import json
from collections import defaultdict
from pathlib import Path
from typing import Any

from rollcam.common.files import write_atomic

from .plan import SHUTTERS, SPLITS, DatasetConfig, subset_name
from .sample import CLASS_NAMES

CARD_JSON = "dataset.json"
CARD_MD = "README.md"
CARD_FORMAT = 1


def coco_document(records: list[dict[str, Any]], shutter: str, split: str, description: str) -> dict[str, Any]:
    """One COCO detection file: images of ``split`` under ``shutter``, labelled boxes with ``iscrowd=0``,
    ignore regions (policy failures) with ``iscrowd=1``. File names are relative to the subset folder."""
    images, anns = [], []
    for rec in records:
        if rec["split"] != split:
            continue
        img = rec["images"][shutter]
        image_id = len(images) + 1
        images.append({"id": image_id, "file_name": img["file"].split("/", 1)[1], "width": img["width"],
                       "height": img["height"]})
        for obj in img["objects"]:
            x0, y0, x1, y1 = obj["box"]
            w, h = round(x1 - x0, 3), round(y1 - y0, 3)
            anns.append({"id": len(anns) + 1, "image_id": image_id, "category_id": CLASS_NAMES.index(obj["class"]) + 1,
                         "bbox": [x0, y0, w, h], "area": round(w * h, 3), "iscrowd": int(obj["ignore"]),
                         "object_id": obj["id"], "visible": obj["visible"], "speed_mps": obj["speed_mps"]})
    return {"info": {"description": description}, "images": images, "annotations": anns,
            "categories": [{"id": i + 1, "name": n} for i, n in enumerate(CLASS_NAMES)]}


def data_yaml(name: str, cfg: DatasetConfig) -> str:
    """Ultralytics dataset file; without ``path`` Ultralytics resolves the splits next to this file."""
    lines = [f"# rollcam dataset {name}: {cfg.summary()}; see ../README.md",
             *(f"{sp}: images/{sp}" for sp in SPLITS), f"nc: {len(CLASS_NAMES)}", "names:",
             *(f"  {i}: {n}" for i, n in enumerate(CLASS_NAMES))]
    return "\n".join(lines) + "\n"


def split_stats(records: list[dict[str, Any]], shutter: str, split: str) -> dict[str, Any]:
    """The study's statistics for one subset and split: images, boxes, boxes per image, mean box area."""
    n_img = n_with = n_box = n_ign = 0
    area = 0.0
    for rec in records:
        if rec["split"] != split:
            continue
        n_img += 1
        objs = rec["images"][shutter]["objects"]
        boxes = [o["box"] for o in objs if not o["ignore"]]
        n_ign += len(objs) - len(boxes)
        n_box += len(boxes)
        n_with += bool(boxes)
        area += sum((b[2] - b[0]) * (b[3] - b[1]) for b in boxes)
    return {"images": n_img, "images_with_boxes": n_with, "boxes": n_box, "ignore_regions": n_ign,
            "boxes_per_image": round(n_box / n_img, 3) if n_img else None,
            "boxes_per_image_with_boxes": round(n_box / n_with, 3) if n_with else None,
            "mean_box_area_px2": round(area / n_box, 1) if n_box else None}


def finalize(root: Path, cfg: DatasetConfig, records: dict[tuple[str, str], dict[str, Any]],
             version: str) -> dict[str, Any]:
    """Write the COCO files, ``data.yaml`` files and the card; return the card."""
    by_speed: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for key in sorted(records):
        by_speed[records[key]["speed"]].append(records[key])
    subsets: dict[str, Any] = {}
    for speed in cfg.speeds:
        recs = by_speed.get(speed, [])
        for shutter in SHUTTERS:
            name = subset_name(speed, shutter)
            sub = root / name
            (sub / "annotations").mkdir(parents=True, exist_ok=True)
            for split in SPLITS:
                for kind in ("images", "labels"):
                    (sub / kind / split).mkdir(parents=True, exist_ok=True)
                doc = coco_document(recs, shutter, split, f"rollcam {name} {split}")
                write_atomic(sub / "annotations" / f"{split}.json", json.dumps(doc).encode())
            write_atomic(sub / "data.yaml", data_yaml(name, cfg).encode())
            subsets[name] = {"speed": speed, "shutter": shutter, "data_yaml": f"{name}/data.yaml",
                             "coco": {sp: f"{name}/annotations/{sp}.json" for sp in SPLITS},
                             "splits": {sp: split_stats(recs, shutter, sp) for sp in SPLITS}}
    scenes = defaultdict(set)
    for rec in records.values():
        scenes[rec["split"]].add(rec["scene"])
    card = {"format": CARD_FORMAT, "kind": "rollcam-dataset", "rollcam_version": version, "config": cfg.to_json(),
            "classes": list(CLASS_NAMES), "pairs": len(records), "content_sha256": content_digest(records),
            "scenes_per_split": {sp: sorted(scenes[sp]) for sp in SPLITS},
            "scene_seeds": {str(r["scene"]): r["scene_seed"]
                            for r in sorted(records.values(), key=lambda r: r["scene"])},
            "subsets": subsets}
    write_atomic(root / CARD_JSON, (json.dumps(card, indent=1) + "\n").encode())
    write_atomic(root / CARD_MD, card_markdown(card).encode())
    return card


def content_digest(records: dict[tuple[str, str], dict[str, Any]]) -> str:
    """One SHA-256 over every file of the samples (each file's name, size and SHA-256, in sample order): two
    builds with the same digest hold the same images and labels byte for byte, so what was measured on one
    (a model's test scores) stands for the other."""
    h = hashlib.sha256()
    for key in sorted(records):
        for rel, d in sorted(records[key].get("files", {}).items()):
            h.update(f"{rel} {d['bytes']} {d['sha256']}\n".encode())
    return h.hexdigest()


def card_markdown(card: dict[str, Any]) -> str:
    """The human-readable dataset card."""
    c = card["config"]
    p = c["policy"]
    policy = (f"- label policy: a person is labelled when its box is at least {p['min_width_px']:g} x "
              f"{p['min_height_px']:g} px and at least {p['min_visible']:.0%} of it is unoccluded; smaller or more "
              "hidden people are ignore regions (COCO `iscrowd=1`, absent from YOLO labels)")
    if c.get("kind") == "footage":
        head = _footage_head(card, policy)
    else:
        head = _emu_head(card, policy)
    out = [*head,
        "## Statistics (labelled boxes)", "",
        "| dataset | split | images | boxes | boxes/image | boxes/image with boxes | mean box area px² | ignore |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for name, sub in card["subsets"].items():
        for sp, st in sub["splits"].items():
            out.append(f"| {name} | {sp} | {st['images']} | {st['boxes']} | {st['boxes_per_image']} | "
                       f"{st['boxes_per_image_with_boxes']} | {st['mean_box_area_px2']} | {st['ignore_regions']} |")
    where = ("the `file:` URI that reproduces it (`rollcam capture URI --shutter both --frames 1`)"
             if c.get("kind") == "footage" else
             "the `emu:` URI that reproduces it (`rollcam capture URI --shutter both --frames 1`)")
    out += ["", "## Layout", "",
            "`<speed>_<gs|rs>/` is an Ultralytics dataset (`data.yaml`, `images/<split>/`, `labels/<split>/`) with "
            "COCO files in `annotations/<split>.json`; `records/<speed>/<sample>.json` holds each pair's full "
            f"ground truth and {where}.",
            ""]
    return "\n".join(out)


def _footage_head(card: dict[str, Any], policy: str) -> list[str]:
    """The card's opening and parameters for a dataset composed from footage."""
    c = card["config"]
    return [
        "# rollcam paired GS/RS dataset from footage", "",
        f"Generated by `rollcam dataset --from-footage` (rollcam {card['rollcam_version']}). {card['pairs']} GS/RS "
        "pairs: each RS image is composed line by line from global-shutter footage, with the footage frame at its "
        "start as its GS partner; labels are composed from the footage's own per-frame labels the same way (exact "
        "from masks, within the stated bound from boxes: see docs/datasets.md).", "",
        "## Parameters", "",
        f"- source `{c['source']}`; frames {c['frames'] or 'every composed frame'}",
        f"- split fractions {c['split_fractions']} in contiguous blocks of time (train first, then val, then test)",
        f"- images `{c['image_format']}`", policy, "",
    ]


def _emu_head(card: dict[str, Any], policy: str) -> list[str]:
    """The card's opening and parameters for a dataset of emulated scenes."""
    c = card["config"]
    return [
        "# rollcam paired GS/RS pedestrian dataset", "",
        f"Generated by `rollcam dataset` (rollcam {card['rollcam_version']}). {card['pairs']} GS/RS pairs: each pair "
        "is one instant of one scene camera rendered with a global and a rolling shutter, labelled from exact "
        "ground truth (GS images with the objects' boxes at the frame's reference time, RS images with the union "
        "of each object's per-row extents at each row's own time).", "",
        "## Parameters", "",
        f"- sensor `{c['sensor']}`, size {c['size'] or 'sensor default'}, ego-motion `{c['ego']}`, "
        f"{c['pedestrians']} pedestrians per scene",
        f"- {c['scenes']} scenes x {c['cameras']} cameras x times of day {', '.join(c['times'])}; "
        f"speeds {', '.join(c['speeds'])}; frames {c['frames'] or 'full grid'}",
        f"- seed {c['seed']}; split fractions {c['split_fractions']} assigned by scene "
        f"(train scenes {_span(card['scenes_per_split']['train'])}, val {_span(card['scenes_per_split']['val'])}, "
        f"test {_span(card['scenes_per_split']['test'])})",
        f"- images `{c['image_format']}`" + (f", raw format `{c['raw_format']}`" if c["raw_format"] else "")
        + (f", extra source options `{c['emu_options']}`" if c["emu_options"] else ""),
        policy, "",
    ]


def _span(ids: list[int]) -> str:
    if not ids:
        return "none"
    if len(ids) == 1:
        return str(ids[0])
    return f"{ids[0]}..{ids[-1]}" if ids == list(range(ids[0], ids[-1] + 1)) else ",".join(map(str, ids))
