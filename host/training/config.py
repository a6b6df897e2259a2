"""What a training run is: its validated, frozen configuration (the key a resumed run must match)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from rollcam.common.errors import ConfigError

from .background import DEFAULT_KINDS, check_kinds
from .labels import check_arm
from .model import model_size

INPUTS = ("rgb", "raw")


@dataclass(frozen=True)
class TrainConfig:
    """Everything that decides a run's weights: dataset, subsets, model, schedule, seed, input, threads.

    ``subsets``/``val_subsets`` empty: every subset of the dataset (validation: the training subsets).
    ``steps`` caps the optimiser steps of each epoch (None: the whole training split), for tiny runs and tests.
    ``scenes``/``cameras`` keep the training images of the first N training scenes / camera views only (the
    study's Fig. 4: accuracy against the diversity of the training set).
    ``labels`` is the label arm of the RS images (``exact``, ``gs`` or ``hand``; ``rollcam.host.training.labels``),
    for training and validation alike.
    ``ema`` > 0 keeps an exponential moving average of the weights with that decay, which validation and the
    export use instead of the raw weights (0: off).
    ``background`` > 0 adds that many background images (no person: flat frames, crops of person-free regions,
    empty streets; ``rollcam.host.training.background``) per training image (0: none), of the kinds
    ``background_kinds`` in turn.
    """

    dataset: str
    subsets: tuple[str, ...] = ()
    val_subsets: tuple[str, ...] = ()
    model: str = "nano"
    epochs: int = 30
    imgsz: tuple[int, int] = (640, 360)
    batch: int = 16
    lr: float = 2e-3
    weight_decay: float = 5e-4
    seed: int = 0
    input: str = "rgb"
    init: str | None = None
    threads: int = 1
    steps: int | None = None
    val_every: int = 1
    scenes: int | None = None
    cameras: int | None = None
    ema: float = 0.0
    labels: str = "exact"
    background: float = 0.0
    background_kinds: tuple[str, ...] = DEFAULT_KINDS

    def __post_init__(self) -> None:
        model_size(self.model)
        for name, value in (("--epochs", self.epochs), ("--batch", self.batch), ("--threads", self.threads),
                            ("--val-every", self.val_every)):
            if not isinstance(value, int) or value < 1:
                raise ConfigError(f"{name} must be an integer >= 1, got {value!r}")
        for name, value in (("--steps", self.steps), ("--scenes", self.scenes), ("--cameras", self.cameras)):
            if value is not None and value < 1:
                raise ConfigError(f"{name} must be an integer >= 1, got {value!r}")
        w, h = self.imgsz
        if w < 32 or h < 32 or w % 4 or h % 4:
            raise ConfigError(f"--imgsz {w}x{h}: both sides must be >= 32 and multiples of 4")
        if self.input not in INPUTS:
            raise ConfigError(f"--input {self.input!r} is not one of {list(INPUTS)}")
        if not (0 < self.lr < 1):
            raise ConfigError(f"--lr must be in (0, 1), got {self.lr!r}")
        if not (0 <= self.ema < 1):
            raise ConfigError(f"--ema must be in [0, 1), got {self.ema!r}")
        check_arm(self.labels)
        if not (0 <= self.background <= 1):
            raise ConfigError(f"--background must be in [0, 1] (background images per training image), "
                              f"got {self.background!r}")
        object.__setattr__(self, "background_kinds", check_kinds(tuple(self.background_kinds)))
        if not self.background and self.background_kinds != DEFAULT_KINDS:
            raise ConfigError("--background-kinds sets the kinds of the background images of --background F; "
                              "give --background F > 0 with it")
        if self.background and self.input == "raw":
            raise ConfigError("--background makes RGB pictures; a raw-mosaic model (--input raw) cannot take them")

    @staticmethod
    def added_keys() -> dict[str, Any]:
        """Options added after the first release, with the value that reproduces runs made before them: a
        checkpoint whose config lacks one was trained with that value."""
        return {"ema": 0.0, "labels": "exact", "background": 0.0, "background_kinds": list(DEFAULT_KINDS)}

    def to_json(self) -> dict[str, Any]:
        """Plain-JSON form, stored in checkpoints and the run card."""
        d = asdict(self)
        d["imgsz"] = f"{self.imgsz[0]}x{self.imgsz[1]}"
        d["subsets"], d["val_subsets"] = list(self.subsets), list(self.val_subsets)
        d["background_kinds"] = list(self.background_kinds)
        return d

    @property
    def detector_input(self) -> str:
        """The ``onnx:`` detector's name for this input (``bgr`` pictures or the ``raw`` mosaic)."""
        return "raw" if self.input == "raw" else "bgr"
