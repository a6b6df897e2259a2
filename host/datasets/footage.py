"""Paired GS/RS datasets from footage rendered elsewhere: ``rollcam dataset --from-footage 'file:...&labels=...'``.

The source is a ``file:`` URI that composes RS frames (``line_time_ns=`` or ``sensor=``) and carries per-frame
labels (``labels=``). Each sample is one composed RS frame with the footage frame at its start as its GS
partner, labelled from the footage's labels (``rollcam.sim.footage_labels``). Samples are every composed frame,
or ``frames`` of them evenly spaced; splits are contiguous blocks in time (train first, then val, then test), so
neighbouring, nearly identical frames do not land in two splits. The layout, label files and card are those of
``rollcam dataset`` (one subset per shutter: ``footage_gs``, ``footage_rs``).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

from rollcam.common.errors import ConfigError, SourceError
from rollcam.common.values import parse_query
from rollcam.sim.footage_labels import LabelTrack

from ..sources import open_camera
from .plan import IMAGE_FORMATS, SPLITS, LabelPolicy, Task, split_quotas

FOOTAGE_SPEED = "footage"
"""The one 'speed' of a footage dataset: its subsets are ``footage_gs`` and ``footage_rs``."""
_RESERVED = ("start", "frames")
_TASK_SAMPLES = 16


@dataclass(frozen=True)
class FootageSample:
    """One composed RS frame (``index``) of the footage and its GS partner."""

    split: str
    index: int
    start_ns: int
    speed: str = FOOTAGE_SPEED
    scene: int = 0
    scene_seed: int = 0
    time: str = FOOTAGE_SPEED
    camera: int = 0

    @property
    def name(self) -> str:
        """File stem: the composed frame's index."""
        return f"f{self.index:06d}"

    @property
    def key(self) -> tuple[str, str]:
        """(speed tag, name): unique in the dataset."""
        return FOOTAGE_SPEED, self.name


@dataclass(frozen=True)
class FootageConfig:
    """Everything that decides a footage dataset's content: the ``file:`` source, how many pairs, policy."""

    source: str
    frames: int | None = None  # pairs; None: every composed frame
    split_fractions: tuple[float, float, float] = (0.8, 0.1, 0.1)
    image_format: str = "png"
    policy: LabelPolicy = field(default_factory=LabelPolicy)
    kind: str = "footage"
    speeds: tuple[str, ...] = (FOOTAGE_SPEED,)

    def __post_init__(self) -> None:
        scheme, _, rest = self.source.partition(":")
        if scheme != "file" or not rest:
            raise ConfigError(f"--from-footage {self.source!r} must be a file: URI, e.g. "
                              "'file:frames/?fps=32400&sensor=letsroll&labels=masks/'")
        query = parse_query(rest.partition("?")[2], f"--from-footage {self.source!r}", ConfigError)
        if "labels" not in query:
            raise ConfigError(f"--from-footage {self.source!r} names no labels (add &labels=PATH)")
        if "line_time_ns" not in query and "sensor" not in query:
            raise ConfigError(f"--from-footage {self.source!r} composes no rolling-shutter frames "
                              "(add &line_time_ns=NS or &sensor=NAME)")
        bad = [k for k in _RESERVED if k in query]
        if bad:
            raise ConfigError(f"--from-footage {self.source!r}: {bad[0]}= is chosen per sample; leave it out")
        if self.frames is not None and self.frames < 3:
            raise ConfigError(f"--frames {self.frames!r} must be >= 3 (one pair per split)")
        if self.image_format not in IMAGE_FORMATS:
            raise ConfigError(f"image format {self.image_format!r} is not one of {list(IMAGE_FORMATS)}")
        f = self.split_fractions
        if len(f) != 3 or any(v <= 0 for v in f) or not math.isclose(sum(f), 1.0, abs_tol=1e-6):
            raise ConfigError(f"split fractions {f!r} must be three positive numbers summing to 1")

    def to_json(self) -> dict[str, Any]:
        """Plain-JSON form stored in the dataset card (and compared on resume)."""
        return asdict(self)

    def summary(self) -> str:
        """One line for file headers."""
        return f"footage {self.source}"

    def sample_uri(self, s: FootageSample) -> str:
        """The ``file:`` URI whose first GS/RS pair is this sample."""
        sep = "&" if "?" in self.source else "?"
        return f"{self.source}{sep}start={s.index}&frames=1"

    def plan(self) -> list[Task]:
        """The samples (every composed frame, or ``frames`` evenly spaced), split in contiguous time blocks."""
        with open_camera(self.source) as src:
            _check_labels(self.source, src.labels)  # type: ignore[attr-defined]
            available = src.composed_frames()  # type: ignore[attr-defined]
            start_of = src.frame_start_ns  # type: ignore[attr-defined]
            n = available if self.frames is None else self.frames
            if n > available or available < 3:
                raise ConfigError(f"--from-footage {self.source!r} holds {available} whole rolling-shutter "
                                  f"frames; {'--frames ' + str(n) if self.frames else 'a dataset'} needs "
                                  f"{max(n, 3)}")
            picks = [i * available // n for i in range(n)]
            starts = [start_of(i) for i in picks]
        quotas = split_quotas(n, self.split_fractions)
        splits = [sp for sp, q in zip(SPLITS, quotas, strict=True) for _ in range(q)]
        samples = [FootageSample(sp, i, t) for sp, i, t in zip(splits, picks, starts, strict=True)]
        return [Task(0, FOOTAGE_SPEED, tuple(samples[j:j + _TASK_SAMPLES]))  # type: ignore[arg-type]
                for j in range(0, len(samples), _TASK_SAMPLES)]


def _check_labels(source: str, labels: LabelTrack) -> None:
    """Read every frame's labels once: a bad label file stops the build before it writes anything."""
    try:
        for k in range(len(labels)):
            labels[k]
    except (SourceError, ConfigError) as exc:
        raise SourceError(f"--from-footage {source!r}: {exc}") from None
