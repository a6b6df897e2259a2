"""The label arm of ``rollcam study``: which boxes an RS image is trained and tested with.

The study's RS images were labelled by hand and its GS images by the renderer, so its mAP@0.5:0.95 drop under
RS mixes two causes: the skew itself and the labels. rollcam knows every object's extent on every line, so it
can label the same RS images three ways (``LABEL_ARMS``):

- ``exact``: rollcam's RS box, the union of the object's extent on each line at that line's time (for a walker
  sheared by the readout, the rectangle around the parallelogram);
- ``gs``: the GS box of the same instant (where the object was at the frame's reference time), what a GS
  image of the pair shows: the label a pipeline gets when it reuses the GS labeller's boxes on RS images;
- ``hand``: the exact RS box as a person redraws it (``ANNOTATOR``): every edge moved inwards by a fixed
  fraction of the box's side and jittered by a seeded normal error.

GS images always keep their own (exact) labels: the study labelled them automatically too.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rollcam.common.errors import ConfigError

from ..evaluation.loaders import EvalSet, ImageEntry
from ..evaluation.metrics import Truth
from .study_settings import LABEL_ARMS

STUDY_BOX_AREA_PX2 = {"normal_rs": 7725.0, "normal_gs": 10847.0, "fast_rs": 11465.0, "fast_gs": 11932.0}
"""The study's mean training box areas at 1920x1080 (its Section IV): hand-drawn RS, renderer-drawn GS."""
STUDY_SIZE = (1920, 1080)


@dataclass(frozen=True)
class Annotator:
    """A person drawing a box around a walker, as a seeded error on the exact box.

    ``edge_sd`` is the standard deviation of each edge's placement as a fraction of the drawn box's side
    (independent per edge): 0.029 makes two annotators of the same object agree at a mean IoU of 0.88, the
    agreement of two careful annotators redrawing PASCAL VOC boxes (Papadopoulos et al., "Extreme clicking for
    efficient object annotation", ICCV 2017). ``inset`` moves every edge inwards by that fraction of the side:
    0.078 gives the study's own ratio of hand-drawn RS to rendered GS box area at normal speed
    (7,725 / 10,847 px2 = 0.712 = (1 - 2 x 0.078)^2), where the readout skews a 2 m/s walker by about a pixel
    over its whole height, so the difference is the labelling's. Boxes keep at least ``min_side_px`` per side.
    """

    edge_sd: float = 0.029
    inset: float = 0.078
    min_side_px: float = 1.0

    def draw(self, boxes: np.ndarray, rng: np.random.Generator, width: int = 0, height: int = 0) -> np.ndarray:
        """The boxes (N, 4) ``x0 y0 x1 y1`` as this annotator draws them, clipped to the image when its size is
        given."""
        b = np.asarray(boxes, np.float64).reshape(-1, 4)
        w = (b[:, 2] - b[:, 0])[:, None]
        h = (b[:, 3] - b[:, 1])[:, None]
        side = np.concatenate([w, h, w, h], axis=1)
        move = (self.inset + self.edge_sd * (1 - 2 * self.inset) * rng.standard_normal(b.shape)) * side
        out = b + move * np.array([1.0, 1.0, -1.0, -1.0])
        if width and height:
            out[:, [0, 2]] = out[:, [0, 2]].clip(0, width)
            out[:, [1, 3]] = out[:, [1, 3]].clip(0, height)
        for lo, hi in ((0, 2), (1, 3)):  # a collapsed box keeps min_side_px around its centre
            c = (out[:, lo] + out[:, hi]) / 2
            short = out[:, hi] - out[:, lo] < self.min_side_px
            out[short, lo], out[short, hi] = c[short] - self.min_side_px / 2, c[short] + self.min_side_px / 2
        return out


ANNOTATOR = Annotator()


def check_arm(arm: str) -> str:
    """``arm`` when it is one of ``LABEL_ARMS``; a ConfigError naming the choices otherwise."""
    if arm not in LABEL_ARMS:
        raise ConfigError(f"--labels {arm!r} is not one of {list(LABEL_ARMS)}")
    return arm


def image_rng(seed: int, key: str) -> np.random.Generator:
    """The annotator's generator for one image: a function of the arm's seed and the image's name only, so the
    same image gets the same hand labels in every run, split and subset order."""
    return np.random.default_rng([seed, zlib.crc32(key.encode())])


def relabel(sets: list[EvalSet], arm: str, seed: int = 0,
            annotator: Annotator = ANNOTATOR) -> list[EvalSet]:
    """``sets`` (one split of a rollcam dataset, every subset) with their RS images labelled by ``arm``.

    The ``gs`` arm takes each RS image's labels from the GS image of the same instant (same file name in the
    GS subset of its speed), which needs that subset among ``sets``.
    """
    check_arm(arm)
    if arm == "exact":
        return list(sets)
    gs_truth = {s.speed: {Path(e.key).name: e.truth for e in s.images} for s in sets if s.shutter == "gs"}
    out = []
    for s in sets:
        if s.shutter != "rs":
            out.append(s)
            continue
        entries = []
        for e in s.images:
            name = Path(e.key).name
            if arm == "gs":
                if s.speed not in gs_truth or name not in gs_truth[s.speed]:
                    raise ConfigError(f"--labels gs: RS image {e.key!r} has no GS image of the same instant")
                truth = gs_truth[s.speed][name]
            else:
                t = e.truth
                boxes = annotator.draw(t.boxes, image_rng(seed, name), t.width, t.height)
                truth = Truth.of(boxes, t.classes, t.ignore, t.width, t.height)
            entries.append(ImageEntry(e.key, e.path, e.image_id, truth, e.prepare))
        out.append(EvalSet(s.name, entries, s.class_names, s.speed, s.shutter))
    return out


def box_stats(s: EvalSet, size: tuple[int, int] = STUDY_SIZE) -> dict[str, float]:
    """Labelled boxes of a set: count, per image, mean area in pixels and that area scaled to ``size`` (the
    study's 1920x1080), for the study's table of box sizes."""
    areas, scale = [], None
    for e in s.images:
        keep = ~e.truth.ignore
        b = e.truth.boxes[keep]
        areas += list((b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1]))
        if scale is None and e.truth.width and e.truth.height:
            scale = (size[0] / e.truth.width) * (size[1] / e.truth.height)
    n = len(areas)
    mean = float(np.mean(areas)) if n else 0.0
    return {"boxes": n, "per_image": round(n / max(len(s.images), 1), 3), "mean_area_px2": round(mean, 1),
            "mean_area_study_px2": round(mean * (scale or 1.0), 1)}
