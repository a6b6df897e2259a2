"""Training images from a rollcam dataset: subsets chosen and combined, fitted once, batched with targets.

Labels are read from the dataset's COCO files through the evaluation loaders (the same truth ``rollcam eval``
scores against, ignore regions included), and every image is fitted to the network input by the ``onnx:``
detector's own ``fit_image``, so training sees exactly what inference will feed the exported model. Fitted
images are kept in memory after their first use (uint8, or uint16 for a deep raw mosaic): at 640x360 RGB that
is 0.7 MB per image, so a 3,200-image run holds ~2.2 GB.

Augmentation is a horizontal flip and a brightness/contrast jitter, drawn from the caller's generator. A flip
keeps the physics of both shutters (an RS frame mirrored is the RS frame of the mirrored street: rows are still
read top to bottom); a vertical flip would not, so there is none. A raw mosaic is flipped and shifted by one
column, which keeps its colour sites where the sensor has them.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError

from ..detectors.onnx import fit_image, input_scale
from ..evaluation.loaders import EvalSet, load_rollcam
from .background import DEFAULT_KINDS, Backgrounds
from .labels import relabel
from .loss import build_targets
from .model import STRIDE


@dataclass(frozen=True)
class DatasetInfo:
    """What training needs to know of a dataset folder: its card, subsets and raw format (if any)."""

    root: Path
    card: dict[str, Any]
    subsets: tuple[str, ...]
    raw_format: str | None
    raw_bits: int | None


def open_dataset(root: str | Path) -> DatasetInfo:
    """Read a rollcam dataset's card; a ConfigError when ``root`` is not a finished rollcam dataset."""
    path = Path(root)
    card_path = path / "dataset.json"
    if not card_path.is_file():
        raise ConfigError(f"DATASET {str(root)!r} is not a rollcam dataset folder (no dataset.json; build one with "
                          "'rollcam dataset')")
    card = json.loads(card_path.read_text())
    raw = card.get("config", {}).get("raw_format")
    bits = None
    if raw:
        from rollcam.sim.formats import FORMATS

        layout = FORMATS.get(raw)
        if layout is None or layout.packing != "raw":
            raise ConfigError(f"dataset {str(root)!r} stores raw format {raw!r}, which is not one sample per pixel; "
                              "build it with an unpacked raw format (e.g. --raw RGGB)")
        bits = layout.bits
    return DatasetInfo(path, card, tuple(card["subsets"]), raw, bits)


def check_subsets(info: DatasetInfo, names: tuple[str, ...], flag: str) -> tuple[str, ...]:
    """``names`` (default: every subset), each checked against the dataset's subsets."""
    if not names:
        return info.subsets
    bad = [n for n in names if n not in info.subsets]
    if bad:
        raise ConfigError(f"{flag} {bad[0]!r} is not a subset of {str(info.root)!r} (it has {list(info.subsets)})")
    if len(set(names)) != len(names):
        raise ConfigError(f"{flag} names a subset twice: {list(names)}")
    return names


def load_split(info: DatasetInfo, subsets: tuple[str, ...], split: str, *, scenes: int | None = None,
               cameras: int | None = None, labels: str = "exact") -> list[EvalSet]:
    """The evaluation sets of ``subsets`` at ``split`` (in the order given), keeping only the images of the first
    ``scenes`` scenes and ``cameras`` camera views of the split when given; RS images carry the boxes of the
    label arm ``labels`` (``rollcam.host.training.labels``)."""
    sets = {s.name: s for s in relabel(load_rollcam(info.root, split), labels)}
    chosen = [sets[n] for n in subsets]
    if scenes is None and cameras is None:
        return chosen
    views = [(e, _view(e.key)) for s in chosen for e in s.images]
    keep_scenes = sorted({v[0] for _e, v in views})[:scenes] if scenes else None
    out = []
    for s in chosen:
        kept = [e for e in s.images if (keep_scenes is None or _view(e.key)[0] in keep_scenes)
                and (cameras is None or _view(e.key)[1] < cameras)]
        out.append(EvalSet(s.name, kept, s.class_names, s.speed, s.shutter))
    return out


def _view(key: str) -> tuple[int, int]:
    """(scene, camera) of a dataset image from its name (``s012_noon_c3.png``, ``plan.Sample.name``)."""
    m = _NAME.search(key)
    if m is None:
        raise ConfigError(f"image {key!r} is not named like a rollcam dataset sample (sNNN_TIME_cN)")
    return int(m.group(1)), int(m.group(2))


_NAME = re.compile(r"s(\d+)_[a-z]+_c(\d+)\.[a-z]+$")


class FittedImages:
    """The images of some sets fitted to the network input, with their boxes in input pixels, fitted lazily;
    after them, the background images of ``with_backgrounds`` (no boxes), if any."""

    def __init__(self, sets: list[EvalSet], width: int, height: int, input: str) -> None:
        self.entries = [e for s in sets for e in s.images]
        self.width, self.height, self.input = width, height, input
        self._cache: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._content: dict[int, tuple[float, float, float, float]] = {}
        self.backgrounds: Backgrounds | None = None

    def with_backgrounds(self, fraction: float, seed: int, card: dict[str, Any],
                         kinds: tuple[str, ...] = DEFAULT_KINDS) -> FittedImages:
        """Add ``round(fraction x images)`` background images (``rollcam.host.training.background``) of ``kinds``
        in turn after the dataset's own; returns self."""
        count = round(fraction * len(self.entries))
        self.backgrounds = Backgrounds(count, seed, self, card, kinds) if count else None
        return self

    def __len__(self) -> int:
        return len(self.entries) + (len(self.backgrounds) if self.backgrounds is not None else 0)

    def content(self, i: int) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1): where dataset image ``i`` lies in the input, letterbox bars excluded."""
        self.get(i)
        return self._content[i]

    def get(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(fitted image H x W x C, boxes (N, 4) in input pixels, ignore flags (N,)) of image ``i``."""
        if i >= len(self.entries) and self.backgrounds is not None:
            return (self.backgrounds.get(i - len(self.entries)), np.zeros((0, 4), np.float32),
                    np.zeros(0, bool))
        if i not in self._cache:
            import cv2

            e = self.entries[i]
            flags = cv2.IMREAD_UNCHANGED if self.input == "raw" else cv2.IMREAD_COLOR
            img = cv2.imread(str(e.path), flags)
            if img is None:
                raise ConfigError(f"cannot read training image {str(e.path)!r}")
            if self.input == "raw" and img.ndim != 2:
                raise ConfigError(f"{str(e.path)!r} is not a one-channel raw mosaic (shape {img.shape})")
            fitted, place = fit_image(img, self.width, self.height, input=self.input)
            b = e.truth.boxes.astype(np.float32).copy()
            b[:, [0, 2]] = b[:, [0, 2]] * place.scale_x + place.pad_x
            b[:, [1, 3]] = b[:, [1, 3]] * place.scale_y + place.pad_y
            self._cache[i] = (np.ascontiguousarray(fitted), b, e.truth.ignore.copy())
            h, w = img.shape[:2]
            self._content[i] = (place.pad_x, place.pad_y, place.pad_x + w * place.scale_x,
                                place.pad_y + h * place.scale_y)
        return self._cache[i]


def grid_shape(height: int, width: int) -> tuple[int, int]:
    """The head's grid for an input size (each stride-2 layer rounds up)."""
    for _ in range(STRIDE.bit_length() - 1):
        height, width = (height + 1) // 2, (width + 1) // 2
    return height, width


def make_batch(images: FittedImages, indices: np.ndarray, rng: np.random.Generator | None,
               bits: int | None = None) -> dict[str, np.ndarray]:
    """One batch: ``image`` (B, C, H, W) float32 in 0..1 and the targets of ``build_targets`` stacked;
    ``rng`` None for no augmentation."""
    gh, gw = grid_shape(images.height, images.width)
    imgs, targets = [], []
    for i in indices:
        img, boxes, ignore = images.get(int(i))
        arr = img.astype(np.float32) * np.float32(input_scale(img.dtype, images.input, bits))
        boxes = boxes.copy()
        if rng is not None:
            if rng.random() < 0.5:
                arr, boxes = _hflip(arr, boxes, images.input == "raw")
            gain, offset = rng.uniform(0.75, 1.25), rng.uniform(-0.08, 0.08)
            arr = np.clip(arr * np.float32(gain) + np.float32(offset), 0.0, 1.0)
        imgs.append(arr.transpose(2, 0, 1))
        targets.append(build_targets(boxes, ignore, gh, gw))
    batch = {"image": np.ascontiguousarray(np.stack(imgs), np.float32)}
    for k in targets[0]:
        batch[k] = np.stack([t[k] for t in targets])
    return batch


def _hflip(arr: np.ndarray, boxes: np.ndarray, raw: bool) -> tuple[np.ndarray, np.ndarray]:
    w = arr.shape[1]
    out = arr[:, ::-1]
    shift = 0
    if raw:  # one column over: the mirrored mosaic's colour sites land where the sensor's are
        out = np.concatenate([out[:, 1:], out[:, -1:]], axis=1)
        shift = 1
    flipped = boxes.copy()
    flipped[:, 0] = w - boxes[:, 2] - shift
    flipped[:, 2] = w - boxes[:, 0] - shift
    return np.ascontiguousarray(out), flipped
