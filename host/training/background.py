"""Background images for ``rollcam train --background F``: pictures with no person in them, trained on as images
with no boxes, so that a detector learns that a featureless or person-free picture holds nobody.

A detector trained only on street scenes full of walkers has never been told what *no* person looks like at the
scale of a whole frame: personnet's tried third stage reported frame-high people at scores 0.49-0.57 in flat black,
grey and white frames (docs/training.md). A camera's black start-up frames, a covered lens or a blown-out frame
would fill a detector's log with them. The remedy object detectors use is background images (images without
labels, a few to ten per cent of the training set); here they are of these kinds, taken in turn from the run's
``--background-kinds`` cycle (default ``flat,crop,street``):

- ``flat``: a uniform frame at a level drawn over the whole range (black to white), tinted a little per channel,
  with a gentle linear ramp on half of them and the sensor-like noise of a flat field (0-3 DN);
- ``crop``: a crop of a training image's person-free region (above the highest box, or left or right of every
  box; ignored boxes count as people), scaled up to the whole input: sky, roofs and facades at the scale a
  person would fill, the textures most like a walker's outline;
- ``street``: an empty street rendered as the dataset's own were (its sensor, size, times of day and emu
  options, ``pedestrians=0``), from scene seeds of its own (``STREET_SEED0`` on, none of the dataset's);
- ``edge``: a crop of a training image's person-free band beside a frame edge (left of every box, or right of
  every box), anchored to that edge and scaled up to the whole input, so that what the frame edge cuts (a pole, a
  car's flank, a doorway) stays cut: the tried runs with the first three kinds still reported a person in an empty
  street on a narrow dark object cut by the frame's right edge (docs/training.md).

A kind listed twice in the cycle comes twice as often (``flat,crop,street,street,edge``: two empty streets in five).

Each background is drawn from the run's seed and its index alone, so a resumed run sees the same ones. Streets
are rendered once and kept (as the fitted dataset images are); flat frames and crops are remade on each use.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.common.values import parse_size

KINDS = ("flat", "crop", "street", "edge")
"""Every kind of background image."""
DEFAULT_KINDS = ("flat", "crop", "street")
"""The cycle of kinds when a run names none (the one every run before ``--background-kinds`` used)."""
STREET_SEED0 = 5000
"""First scene seed of the empty streets (the datasets' seeds are drawn from 0..2^31; ``rollcam bench personnet``
tests on 1000..1009)."""
STREETS_PER_SCENE = 5
"""Camera views of one empty street scene before the next seed."""
MARGIN_PX = 2
"""Input pixels kept between a crop and the nearest box."""
MIN_CROP_PX = 24
"""The smallest side (input pixels) of a person-free region worth a crop; smaller ones give a flat frame."""


class TrainingImages(Protocol):
    """What the crops are cut from: the fitted training images (``rollcam.host.training.data.FittedImages``)."""

    entries: list[Any]
    width: int
    height: int
    input: str

    def get(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...

    def content(self, i: int) -> tuple[float, float, float, float]: ...


def check_kinds(kinds: tuple[str, ...], option: str = "--background-kinds: ") -> tuple[str, ...]:
    """``kinds`` when it is a non-empty cycle of known kinds; a ``ConfigError`` naming the problem (after
    ``option``) otherwise."""
    if not kinds:
        raise ConfigError(f"{option}name at least one of {', '.join(KINDS)}")
    if bad := [k for k in kinds if k not in KINDS]:
        raise ConfigError(f"{option}{bad[0]!r} is not a background kind ({', '.join(KINDS)})")
    return tuple(kinds)


class Backgrounds:
    """``count`` background images for a training set: ``get(i)`` is image ``i`` (H x W x 3 uint8, RGB, the
    network input's size), of kind ``kinds[i % len(kinds)]``. ``source``: the fitted training images the crops come
    from (RGB ones: ``TrainConfig`` refuses ``--background`` for a raw-mosaic model); ``card``: the dataset's card
    (how its streets were rendered)."""

    def __init__(self, count: int, seed: int, source: TrainingImages, card: dict[str, Any],
                 kinds: tuple[str, ...] = DEFAULT_KINDS) -> None:
        self.count, self.seed, self.source, self.kinds = count, seed, source, check_kinds(kinds)
        self.width, self.height = source.width, source.height
        self._card = card.get("config", {})
        taken = {int(v) for v in card.get("scene_seeds", {}).values()}
        self._seeds = (s for s in range(STREET_SEED0, STREET_SEED0 + 10**6) if s not in taken)
        self._streets: dict[int, np.ndarray] = {}
        self._street_seed: dict[int, int] = {}

    def __len__(self) -> int:
        return self.count

    def kind(self, i: int) -> str:
        """The kind of background ``i``."""
        return self.kinds[i % len(self.kinds)]

    def _ordinal(self, i: int) -> int:
        """How many backgrounds of ``i``'s kind come before it (which empty street ``i`` is)."""
        cycle, pos = divmod(i, len(self.kinds))
        kind = self.kinds[pos]
        return cycle * self.kinds.count(kind) + self.kinds[:pos].count(kind)

    def get(self, i: int) -> np.ndarray:
        """Background ``i``, the same on every call."""
        if not 0 <= i < self.count:
            raise IndexError(i)
        rng = np.random.default_rng([self.seed, i, 0x6267])
        kind = self.kind(i)
        if kind == "street":
            if i not in self._streets:
                self._streets[i] = self._street(self._ordinal(i))
            return self._streets[i]
        if kind in ("crop", "edge"):
            crop = self._crop(rng, edge=kind == "edge")
            if crop is not None:
                return crop
        return flat_frame(rng, self.width, self.height)

    def _crop(self, rng: np.random.Generator, edge: bool = False) -> np.ndarray | None:
        import cv2

        j = int(rng.integers(len(self.source.entries)))
        img, boxes, _ignore = self.source.get(j)
        content = self.source.content(j)
        if edge:
            region, side = edge_region(boxes, content, rng) or (None, None)
        else:
            region, side = free_region(boxes, content, rng), None
        if region is None:
            return None
        rx0, ry0, rx1, ry1 = region
        aspect = self.width / self.height
        ch = min(ry1 - ry0, (rx1 - rx0) / aspect) * rng.uniform(0.6, 1.0)
        cw = ch * aspect
        if side is None:
            cx = rx0 + rng.uniform(0, rx1 - rx0 - cw)
        else:  # flush with the frame edge the band touches, so what the edge cuts stays cut
            cx = rx0 if side == "left" else rx1 - cw
        cy = ry0 + rng.uniform(0, ry1 - ry0 - ch)
        patch = img[int(cy):int(cy + ch), int(cx):int(cx + cw)]
        return cv2.resize(patch, (self.width, self.height), interpolation=cv2.INTER_LINEAR)

    def _street(self, k: int) -> np.ndarray:
        from ..datasets.plan import DatasetConfig, Sample, sample_uri
        from ..detectors.onnx import fit_image
        from ..sources import open_camera

        scene = k // STREETS_PER_SCENE
        while scene not in self._street_seed:
            self._street_seed[len(self._street_seed)] = next(self._seeds)
        c = self._card
        size = c.get("size")
        times = tuple(c.get("times") or ("noon",))
        cfg = DatasetConfig(sensor=c.get("sensor", "letsroll"),
                            size=parse_size(size) if isinstance(size, str) else None,
                            times=times, pedestrians=0, emu_options=c.get("emu_options", ""))
        sample = Sample("normal", scene, self._street_seed[scene], times[(k // STREETS_PER_SCENE) % len(times)],
                        k % STREETS_PER_SCENE, "train", 0)
        with open_camera(sample_uri(cfg, sample) + "&shutter=rolling&frames=1") as cam:
            picture = cam.read().data
        fitted, _ = fit_image(picture, self.width, self.height)
        return np.ascontiguousarray(fitted)


def flat_frame(rng: np.random.Generator, width: int, height: int) -> np.ndarray:
    """A featureless frame: one level (black to white), a slight tint, on half of them a gentle linear ramp, and
    a flat field's noise; H x W x 3 uint8."""
    level = rng.uniform(0, 255)
    base = np.full((height, width, 3), level, np.float32) + rng.normal(0, 4, 3).astype(np.float32)
    if rng.random() < 0.5:
        angle = rng.uniform(0, 2 * np.pi)
        yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
        ramp = (np.cos(angle) * (xx / width - 0.5) + np.sin(angle) * (yy / height - 0.5)) * rng.uniform(0, 40)
        base += ramp[..., None]
    base += rng.normal(0, rng.uniform(0, 3), base.shape).astype(np.float32)
    return np.clip(np.rint(base), 0, 255).astype(np.uint8)


def free_region(boxes: np.ndarray, content: tuple[float, float, float, float],
                rng: np.random.Generator) -> tuple[float, float, float, float] | None:
    """A rectangle of ``content`` (x0, y0, x1, y1) that no box comes within ``MARGIN_PX`` of: the band above every
    box, or left or right of every box, one drawn among those at least ``MIN_CROP_PX`` on each side (all of
    ``content`` when there is no box); None when none is."""
    if len(boxes) == 0:
        return content
    ok = [b for b in _bands(boxes, content).values() if _big_enough(b)]
    if not ok:
        return None
    return ok[int(rng.integers(len(ok)))]


def edge_region(boxes: np.ndarray, content: tuple[float, float, float, float],
                rng: np.random.Generator) -> tuple[tuple[float, float, float, float], str] | None:
    """A band of ``content`` beside its left or right edge that no box comes within ``MARGIN_PX`` of, and that
    edge (``"left"`` or ``"right"``): one drawn among the bands at least ``MIN_CROP_PX`` on each side (all of
    ``content`` and either edge when there is no box); None when neither is."""
    if len(boxes) == 0:
        return content, ("left", "right")[int(rng.integers(2))]
    ok = [(b, side) for side, b in _bands(boxes, content).items() if side != "top" and _big_enough(b)]
    if not ok:
        return None
    return ok[int(rng.integers(len(ok)))]


def _bands(boxes: np.ndarray, content: tuple[float, float, float, float]) -> dict[str, tuple[float, ...]]:
    """The bands of ``content`` clear of every box by ``MARGIN_PX``: above all of them, left of them, right of
    them (a band may be empty or inside out; ``_big_enough`` says which are worth a crop)."""
    x0, y0, x1, y1 = content
    top = float(boxes[:, 1].min()) - MARGIN_PX
    left = float(boxes[:, 0].min()) - MARGIN_PX
    right = float(boxes[:, 2].max()) + MARGIN_PX
    return {"top": (x0, y0, x1, min(y1, top)), "left": (x0, y0, min(x1, left), y1),
            "right": (max(x0, right), y0, x1, y1)}


def _big_enough(band: tuple[float, ...]) -> bool:
    return band[2] - band[0] >= MIN_CROP_PX and band[3] - band[1] >= MIN_CROP_PX
