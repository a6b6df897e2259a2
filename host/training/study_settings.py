"""The settings of ``rollcam study`` (``quick``, ``reduced``, ``full``) and the names of its dataset subsets.

Read by the study's runner (``rollcam.host.training.study``) and by its report (``study_report``), so neither
imports the other's way back.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

SHUTTERS = ("gs", "rs")


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

    def to_json(self) -> dict[str, Any]:
        """Plain JSON (the report's ``settings``)."""
        d = asdict(self)
        d["size"] = f"{self.size[0]}x{self.size[1]}"
        return d


QUICK = StudySettings(
    name="quick", size=(192, 108), frames_per_speed=10, scenes=6, cameras=2, times=("noon",),
    speeds=("normal", "fast"), model="pico", epochs=2, steps=2, batch=4, lr=4e-3, seeds=(0, 1, 2),
    t3_speeds=("fast",), raw_speeds=("fast",), fig4_subset="fast_rs", fig4_scenes=(1,), fig4_cameras=(1,),
    pedestrians=10, val_every=2)
REDUCED = StudySettings(
    name="reduced", size=(320, 180), frames_per_speed=200, scenes=20, cameras=5, times=("morning", "noon", "dusk"),
    speeds=("normal", "5", "fast", "20"), model="pico", epochs=40, steps=None, batch=16, lr=6e-3, seeds=(0, 1, 2),
    t3_speeds=("normal", "fast"), raw_speeds=("fast",), fig4_subset="fast_rs", fig4_scenes=(4, 8),
    fig4_cameras=(1, 3))
FULL = StudySettings(
    name="full", size=(960, 540), frames_per_speed=1000, scenes=40, cameras=5,
    times=("dawn", "morning", "noon", "afternoon", "dusk"), speeds=("normal", "5", "fast", "20"), model="small",
    epochs=100, steps=None, batch=16, lr=2e-3, seeds=(0, 1, 2, 3, 4), t3_speeds=("normal", "fast"),
    raw_speeds=("normal", "fast"), fig4_subset="fast_rs", fig4_scenes=(4, 8, 16), fig4_cameras=(1, 2, 3))
SETTINGS = {s.name: s for s in (QUICK, REDUCED, FULL)}
"""``--setting`` names. ``full`` is the study's design (1,000 pairs per speed; at half its 1080p, so the fitted
images of a run fit in memory) for a GPU; ``reduced`` the CPU setting documented to finish in 2 hours on 2
cores (``--workers 2``); ``quick`` the CI-sized check."""


def subset(speed: str, shutter: str) -> str:
    """The dataset folder of a speed and shutter (``fast_rs``, ``x5_gs``)."""
    from ..datasets.plan import subset_name

    return subset_name(speed, shutter)
