"""What a dataset run renders: its configuration, and the seeded plan of samples and tasks derived from it.

The plan is a pure function of the configuration (seed included): which scenes exist and their seeds, which
split each scene belongs to (a scene is in exactly one split), which (scene, time of day, camera) instants
are drawn, at which device time, and how they group into tasks. Nothing here renders; workers receive
``Task`` objects and the same config, so any executor (in process, a process pool, a Dask cluster) renders
exactly the same samples.
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.sim.scenegen import DATASET_TIMES, SPEED_PRESETS, TIMES_OF_DAY, parse_speed

SPLITS = ("train", "val", "test")
SHUTTERS = ("gs", "rs")
STUDY_SCENES = 40
STUDY_CAMERAS = 5
MAX_CAMERAS = 5  # cameras a street scene has
IMAGE_FORMATS = ("png", "jpg")


@dataclass(frozen=True)
class LabelPolicy:
    """Which objects become labels. An object whose box (in the image's own shutter) is at least
    ``min_width_px`` x ``min_height_px`` and that is at least ``min_visible`` unoccluded is labelled; one
    that shows but fails the policy becomes an *ignore* region (COCO ``iscrowd=1``: detecting it is neither
    rewarded nor punished; absent from the YOLO labels); one with no visible pixel is dropped."""

    min_width_px: float = 6.0
    min_height_px: float = 16.0
    min_visible: float = 0.3

    def classify(self, box: tuple[float, float, float, float] | None, visible: float) -> str | None:
        """``'label'``, ``'ignore'`` or None (not in the image)."""
        if box is None or visible <= 0.0:
            return None
        w, h = box[2] - box[0], box[3] - box[1]
        if w <= 0 or h <= 0:
            return None
        ok = w >= self.min_width_px and h >= self.min_height_px and visible >= self.min_visible
        return "label" if ok else "ignore"


@dataclass(frozen=True)
class DatasetConfig:
    """Everything that decides a dataset's content. Two runs with equal configs write identical labels."""

    sensor: str = "letsroll"
    size: tuple[int, int] | None = None  # None: the sensor's default mode
    scenes: int = STUDY_SCENES
    cameras: int = STUDY_CAMERAS
    times: tuple[str, ...] = DATASET_TIMES
    speeds: tuple[str, ...] = ("normal", "fast")
    frames: int | None = None  # total GS/RS pairs over all speeds; None: the full grid
    split_fractions: tuple[float, float, float] = (0.8, 0.1, 0.1)
    ego: str = "none"
    pedestrians: int = 20
    seed: int = 0
    image_format: str = "png"
    raw_format: str | None = None  # passed to the emu: source as format=
    emu_options: str = ""  # extra emu: query options, e.g. "exposure_us=2000&gain=2"
    window_s: float = 3.0  # instants are drawn uniformly in the first window_s seconds of each stream
    policy: LabelPolicy = field(default_factory=LabelPolicy)

    def __post_init__(self) -> None:
        if not self.scenes >= 3:
            raise ConfigError(f"--scenes must be >= 3 (one per split at least), got {self.scenes!r}")
        if not 1 <= self.cameras <= MAX_CAMERAS:
            raise ConfigError(f"--cameras must be 1..{MAX_CAMERAS}, got {self.cameras!r}")
        bad = [t for t in self.times if t not in TIMES_OF_DAY]
        if bad or not self.times:
            raise ConfigError(f"--times {list(self.times)!r}: each must be one of {list(TIMES_OF_DAY)}")
        if not self.speeds or len(set(self.speeds)) != len(self.speeds):
            raise ConfigError(f"--speeds {list(self.speeds)!r} must be distinct and non-empty")
        for s in self.speeds:
            parse_speed(s)
        if self.frames is not None and self.frames < len(self.speeds) * 3:
            raise ConfigError(f"--frames {self.frames!r} must be >= 3 per speed (one pair per split), "
                              f"i.e. >= {3 * len(self.speeds)}")
        if self.image_format not in IMAGE_FORMATS:
            raise ConfigError(f"image format {self.image_format!r} is not one of {list(IMAGE_FORMATS)}")
        f = self.split_fractions
        if len(f) != 3 or any(v <= 0 for v in f) or not math.isclose(sum(f), 1.0, abs_tol=1e-6):
            raise ConfigError(f"split fractions {f!r} must be three positive numbers summing to 1")
        if not self.window_s > 0:
            raise ConfigError(f"window_s must be > 0, got {self.window_s!r}")

    def to_json(self) -> dict[str, Any]:
        """Plain-JSON form stored in the dataset card (and compared on resume)."""
        d = asdict(self)
        d["size"] = None if self.size is None else f"{self.size[0]}x{self.size[1]}"
        return d

    def summary(self) -> str:
        """One line for file headers."""
        return f"sensor {self.sensor}, seed {self.seed}"

    def plan(self) -> list[Task]:
        """The seeded plan (``make_plan``)."""
        return make_plan(self)

    def sample_uri(self, s: Sample) -> str:
        """The ``emu:`` URI of one sample (``sample_uri``)."""
        return sample_uri(self, s)


@dataclass(frozen=True)
class Sample:
    """One instant of one scene camera at one walker speed: a GS image and an RS image with their labels."""

    speed: str
    scene: int
    scene_seed: int
    time: str
    camera: int
    split: str
    start_ns: int

    @property
    def name(self) -> str:
        """File stem, unique within a speed: scene, time of day, camera."""
        return f"s{self.scene:03d}_{self.time}_c{self.camera}"

    @property
    def key(self) -> tuple[str, str]:
        """(speed tag, name): unique in the dataset."""
        return speed_tag(self.speed), self.name


@dataclass(frozen=True)
class Task:
    """A unit of work for an executor: every planned sample of one scene at one time of day."""

    scene: int
    time: str
    samples: tuple[Sample, ...]


def speed_tag(speed: str) -> str:
    """Folder-safe name of a speed: ``normal``, ``fast``, or ``x2.5`` for a multiplier."""
    s = str(speed).lower()
    if s in SPEED_PRESETS or s == "footage":  # footage datasets (host.datasets.footage) have this one speed
        return s
    return "x" + re.sub(r"[^0-9.]", "_", f"{parse_speed(s):g}")


def subset_name(speed: str, shutter: str) -> str:
    """The folder of one of the datasets: ``normal_gs``, ``fast_rs``..."""
    return f"{speed_tag(speed)}_{shutter}"


def split_of_scenes(n_scenes: int, fractions: tuple[float, float, float]) -> list[str]:
    """The split of each scene index: the first ~80% train, then val, then test (each at least one)."""
    n_val = max(1, round(n_scenes * fractions[1]))
    n_test = max(1, round(n_scenes * fractions[2]))
    n_train = n_scenes - n_val - n_test
    if n_train < 1:
        raise ConfigError(f"{n_scenes} scenes cannot fill three splits {fractions!r}")
    return ["train"] * n_train + ["val"] * n_val + ["test"] * n_test


def split_quotas(total: int, fractions: tuple[float, float, float]) -> list[int]:
    """Split ``total`` samples by fractions, largest remainders first, at least one each."""
    raw = [total * f for f in fractions]
    q = [max(1, math.floor(v)) for v in raw]
    order = sorted(range(3), key=lambda i: raw[i] - math.floor(raw[i]), reverse=True)
    i = 0
    while sum(q) < total:
        q[order[i % 3]] += 1
        i += 1
    while sum(q) > total:
        j = max(range(3), key=lambda k: q[k])
        q[j] -= 1
    return q


def make_plan(cfg: DatasetConfig) -> list[Task]:
    """The seeded list of tasks (sorted), each holding its samples. Same config, same plan."""
    rng = np.random.default_rng([cfg.seed, 0x5CE4E])
    scene_seeds = [int(s) for s in rng.choice(2**31 - 1, size=cfg.scenes, replace=False)]
    splits = split_of_scenes(cfg.scenes, cfg.split_fractions)
    grid = {sp: [(sc, t, c) for sc in range(cfg.scenes) if splits[sc] == sp for t in cfg.times
                 for c in range(cfg.cameras)] for sp in SPLITS}
    n_speeds = len(cfg.speeds)
    if cfg.frames is None:
        chosen = {sp: grid[sp] for sp in SPLITS}
    else:
        per_speed = cfg.frames // n_speeds
        if cfg.frames % n_speeds:
            raise ConfigError(f"--frames {cfg.frames} is not a multiple of the {n_speeds} speed(s)")
        chosen = {}
        for sp, quota in zip(SPLITS, split_quotas(per_speed, cfg.split_fractions), strict=True):
            cells = grid[sp]
            if quota > len(cells):
                raise ConfigError(f"--frames {cfg.frames}: split {sp!r} needs {quota} instants per speed but its "
                                  f"scenes hold {len(cells)}; raise --scenes, --cameras or --times")
            pick = np.random.default_rng([cfg.seed, 0x5B5, SPLITS.index(sp)]).permutation(len(cells))[:quota]
            chosen[sp] = sorted(cells[i] for i in pick)
    window_ns = round(cfg.window_s * 1e9)
    tasks: dict[tuple[int, str], list[Sample]] = {}
    for sp in SPLITS:
        for sc, t, c in chosen[sp]:
            # One instant per scene camera and time of day, shared by every speed: the normal and fast
            # datasets show the same crowd at the same moment, only faster.
            t_idx = list(TIMES_OF_DAY).index(t)
            start = int(np.random.default_rng([cfg.seed, sc, t_idx, c]).integers(0, window_ns // 1000)) * 1000
            for speed in cfg.speeds:
                tasks.setdefault((sc, t), []).append(Sample(speed, sc, scene_seeds[sc], t, c, sp, start))
    return [Task(sc, t, tuple(sorted(v, key=lambda s: (s.camera, cfg.speeds.index(s.speed)))))
            for (sc, t), v in sorted(tasks.items(), key=lambda kv: (kv[0][0], list(TIMES_OF_DAY).index(kv[0][1])))]


def sample_uri(cfg: DatasetConfig, s: Sample) -> str:
    """The ``emu:`` URI whose first GS/RS pair is this sample (``rollcam capture URI --shutter both --frames 1``
    reproduces it)."""
    opts = ["scene=street", f"seed={s.scene_seed}", f"speed={s.speed}", f"camera={s.camera}", f"time={s.time}",
            f"pedestrians={cfg.pedestrians}", f"ego={cfg.ego}", f"start_ns={s.start_ns}"]
    if cfg.size is not None:
        opts.append(f"size={cfg.size[0]}x{cfg.size[1]}")
    if cfg.raw_format:
        opts.append(f"format={cfg.raw_format}")
    if cfg.emu_options:
        opts.append(cfg.emu_options.lstrip("?&"))
    return f"emu:{cfg.sensor}?" + "&".join(opts)
