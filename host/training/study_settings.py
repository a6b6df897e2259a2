"""The settings of ``rollcam study`` (``quick``, ``reduced``, ``medium``, ``full``) and its subsets' names.

Read by the study's runner (``rollcam.host.training.study``) and by its report (``study_report``), so neither
imports the other's way back.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

SHUTTERS = ("gs", "rs")
LABEL_ARMS = ("exact", "gs", "hand")
"""The labels an RS image can be trained and tested with (``rollcam.host.training.labels``; ``rollcam train
--labels``), here so the CLI names them without importing numpy."""
EXPERIMENTS = ("t1", "t3", "speed", "raw", "fig4", "labels", "coco")
"""``rollcam study --only`` names (``rollcam.host.training.study`` says what each is)."""


@dataclass(frozen=True)
class StudySettings:
    """One setting of the study: dataset design, model and schedule, seeds and what each experiment varies."""

    name: str
    size: tuple[int, int]
    frames_per_speed: int
    scenes: int
    cameras: int
    times: tuple[str, ...]
    speeds: tuple[str, ...]          # the dataset's speeds; Table 1 uses normal and fast
    model: str
    epochs: int
    steps: int | None
    batch: int
    lr: float
    seeds: tuple[int, ...]
    t3_speeds: tuple[str, ...]       # speeds of the GS+RS models
    raw_speeds: tuple[str, ...]      # speeds of the raw-mosaic models (a second dataset, --raw RGGB)
    fig4_subset: str
    fig4_scenes: tuple[int, ...]     # training scenes of the Fig. 4 points (the full set is t1's run)
    fig4_cameras: tuple[int, ...]
    pedestrians: int = 20
    val_every: int = 5
    label_speeds: tuple[str, ...] = ()   # speeds of the label arm (RS models trained on GS and hand labels)
    # Table 2: the COCO-trained detectors, not fine-tuned, as detector specs (a low threshold: mAP wants the whole
    # precision-recall curve; HOG's 64x128 window wants walkers upscaled to ~100 px tall)
    coco_detectors: tuple[str, ...] = ("ssdlite?conf=0.01", "hog?hit=-0.5&upscale=4")
    split: tuple[float, float, float] = (0.8, 0.1, 0.1)  # fractions of the scenes in train, val, test
    base_frames: int = 0             # > 0: every run fine-tunes one base model trained on GS pairs of other scenes
    base_scenes: int = 0
    base_seed: int = 1               # the base dataset's seed (its scenes are not the study's)
    base_epochs: int = 0
    base_lr: float = 0.0

    def to_json(self) -> dict[str, Any]:
        """Plain JSON (the report's ``settings``)."""
        d = asdict(self)
        d["size"] = f"{self.size[0]}x{self.size[1]}"
        return d


QUICK = StudySettings(
    name="quick", size=(192, 108), frames_per_speed=10, scenes=6, cameras=2, times=("noon",),
    speeds=("normal", "fast"), model="pico", epochs=2, steps=2, batch=4, lr=4e-3, seeds=(0, 1, 2),
    t3_speeds=("fast",), raw_speeds=("fast",), fig4_subset="fast_rs", fig4_scenes=(1,), fig4_cameras=(1,),
    pedestrians=10, val_every=2, label_speeds=("fast",))
REDUCED = StudySettings(
    name="reduced", size=(320, 180), frames_per_speed=200, scenes=20, cameras=5, times=("morning", "noon", "dusk"),
    speeds=("normal", "5", "fast", "20"), model="pico", epochs=40, steps=None, batch=16, lr=6e-3, seeds=(0, 1, 2),
    t3_speeds=("normal", "fast"), raw_speeds=("fast",), fig4_subset="fast_rs", fig4_scenes=(4, 8),
    fig4_cameras=(1, 3), label_speeds=("fast", "20"))
FULL = StudySettings(
    name="full", size=(960, 540), frames_per_speed=1000, scenes=40, cameras=5,
    times=("dawn", "morning", "noon", "afternoon", "dusk"), speeds=("normal", "5", "fast", "20"), model="small",
    epochs=100, steps=None, batch=16, lr=2e-3, seeds=(0, 1, 2, 3, 4), t3_speeds=("normal", "fast"),
    raw_speeds=("normal", "fast"), fig4_subset="fast_rs", fig4_scenes=(4, 8, 16), fig4_cameras=(1, 2, 3),
    label_speeds=("normal", "5", "fast", "20"), coco_detectors=("ssdlite?conf=0.01", "hog?hit=-0.5"))
MEDIUM = StudySettings(
    name="medium", size=(640, 360), frames_per_speed=800, scenes=40, cameras=5,
    times=("dawn", "morning", "noon", "afternoon", "dusk"),
    speeds=("normal", "fast"), model="nano", epochs=12, steps=None, batch=8, lr=2e-3, seeds=(0, 1, 2, 3, 4),
    t3_speeds=(), raw_speeds=(), fig4_subset="fast_rs", fig4_scenes=(), fig4_cameras=(),
    label_speeds=("normal", "fast"), coco_detectors=("ssdlite?conf=0.01", "hog?hit=-0.5&upscale=2"),
    val_every=4, split=(0.5, 0.1, 0.4), base_frames=800, base_scenes=40, base_seed=1, base_epochs=24, base_lr=5e-3)
SETTINGS = {s.name: s for s in (QUICK, REDUCED, MEDIUM, FULL)}
"""``--setting`` names. ``full`` is the study's design (1,000 pairs per speed; at half its 1080p, so the fitted
images of a run fit in memory) for a GPU; ``medium`` the CPU setting sized to resolve a 5 % relative
mAP@0.5:0.95 difference (docs/training.md, "Power of the study"): 640x360, the shipped detector's ``nano``
capacity, every run fine-tuned from one base model trained on GS images of other scenes, Table 1 and the
label arm only; ``reduced`` the CPU setting documented to finish in 2 hours on 2 cores (``--workers 2``);
``quick`` the CI-sized check."""


def subset(speed: str, shutter: str) -> str:
    """The dataset folder of a speed and shutter (``fast_rs``, ``x5_gs``)."""
    from ..datasets.plan import subset_name

    return subset_name(speed, shutter)
