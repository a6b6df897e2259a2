"""``rollcam study``: the study's experiments end to end: build the datasets, train every model, test each one.

The experiments (``plan_jobs``), each a set of training runs with ``seeds`` seeds where a difference is a
headline one:

- ``t1``: one model per subset (normal/fast x GS/RS), tested on the GS and RS test splits of its speed; its
  diagonal is the study's Table 1, its off-diagonal and GS+RS cells Table 3 (train GS / test RS and so on);
- ``t3``: models trained on GS and RS together, the missing cells of Table 3;
- ``speed``: GS and RS models at more walker speeds (1x, 5x, 10x, 20x): the RS penalty against speed;
- ``raw``: GS and RS models on the raw mosaic (ISP-less input), the same comparison without an ISP;
- ``fig4``: one RS subset trained on fewer scenes and fewer camera views (the study's Fig. 4).

Every run is an ordinary ``rollcam train`` folder under ``OUT/runs/`` with its test results beside it
(``test.json``): a rerun of the study resumes an interrupted run and skips finished ones. Runs go to the
dataset builder's executors (``--workers N`` processes, one torch thread each, or a Dask cluster).
"""

from __future__ import annotations

import functools
import json
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from rollcam.common.errors import ConfigError
from rollcam.common.files import output_dir, write_atomic

from .study_report import write_report
from .study_settings import SHUTTERS, StudySettings, subset


@dataclass(frozen=True)
class Job:
    """One training run and what it is tested on: ``key`` names its folder under ``OUT/runs/``."""

    key: str
    group: str
    speed: str
    train: tuple[str, ...]
    seed: int
    raw: bool = False
    scenes: int | None = None
    cameras: int | None = None


def plan_jobs(s: StudySettings) -> list[Job]:
    """Every training run of the study, each once (an experiment that needs a run another has made shares it)."""
    jobs: list[Job] = []
    for speed in s.speeds:
        group = "t1" if speed in ("normal", "fast") else "speed"
        for sh in SHUTTERS:
            jobs += [Job(f"{subset(speed, sh)}_s{seed}", group, speed, (subset(speed, sh),), seed) for seed in s.seeds]
    for speed in s.t3_speeds:
        both = (subset(speed, "gs"), subset(speed, "rs"))
        jobs += [Job(f"{subset(speed, 'gsrs')}_s{seed}", "t3", speed, both, seed) for seed in s.seeds]
    for speed in s.raw_speeds:
        for sh in SHUTTERS:
            jobs += [Job(f"raw_{subset(speed, sh)}_s{seed}", "raw", speed, (subset(speed, sh),), seed, raw=True)
                     for seed in s.seeds]
    f4_speed = next(sp for sp in s.speeds if s.fig4_subset.startswith(subset(sp, "")))
    jobs += [Job(f"{s.fig4_subset}_scenes{n}_s0", "fig4", f4_speed, (s.fig4_subset,), s.seeds[0], scenes=n)
             for n in s.fig4_scenes]
    jobs += [Job(f"{s.fig4_subset}_cams{n}_s0", "fig4", f4_speed, (s.fig4_subset,), s.seeds[0], cameras=n)
             for n in s.fig4_cameras]
    return jobs


def dataset_configs(s: StudySettings) -> dict[str, Any]:
    """The study's datasets: ``rgb`` (every speed) and ``raw`` (the raw-mosaic speeds), same scenes and instants."""
    from ..datasets.plan import DatasetConfig

    rgb = DatasetConfig(size=s.size, scenes=s.scenes, cameras=s.cameras, times=s.times, speeds=s.speeds,
                        frames=s.frames_per_speed * len(s.speeds), pedestrians=s.pedestrians, seed=0)
    out = {"rgb": rgb}
    if s.raw_speeds:
        out["raw"] = replace(rgb, speeds=s.raw_speeds, frames=s.frames_per_speed * len(s.raw_speeds),
                             raw_format="RGGB")
    return out


def run_job(job: Job, s: StudySettings, root: str) -> dict[str, Any]:
    """Train (or resume, or find finished) one run and test it; the result is also ``runs/KEY/test.json``."""
    from .config import TrainConfig
    from .trainer import train

    run_dir = Path(root) / "runs" / job.key
    done = run_dir / "test.json"
    if done.is_file():
        return json.loads(done.read_text())
    data = Path(root) / "data" / ("raw" if job.raw else "rgb")
    cfg = TrainConfig(dataset=str(data), subsets=job.train, model=s.model, epochs=s.epochs, imgsz=s.size,
                      batch=s.batch, lr=s.lr, seed=job.seed, input="raw" if job.raw else "rgb", threads=1,
                      steps=s.steps, val_every=s.val_every, scenes=job.scenes, cameras=job.cameras)
    t0 = time.monotonic()
    result = train(cfg, run_dir, device="auto", progress=False)
    t1 = time.monotonic()
    tests = test_model(result.model_path, data, job.speed)
    doc = {"job": asdict(job), "test": tests, "train_s": round(t1 - t0, 3), "test_s": round(time.monotonic() - t1, 3),
           "val": result.card.get("final")}
    write_atomic(done, (json.dumps(doc, indent=1) + "\n").encode())
    return doc


def test_model(model: Path, dataset: Path, speed: str) -> dict[str, Any]:
    """The model on the test splits of ``speed``: GS, RS, and GS and RS pooled (``gsrs``)."""
    from ..detectors import load_detector
    from ..evaluation.loaders import load_rollcam, run_detector
    from ..evaluation.metrics import evaluate

    sets = {s.name: s for s in load_rollcam(dataset, "test")}
    det = load_detector(f"onnx:{model}?conf=0.01&threads=1")
    try:
        dets = {sh: run_detector(det, sets[subset(speed, sh)]) for sh in SHUTTERS}
    finally:
        det.close()
    keep = ("P", "R", "mAP50", "mAP50_95")
    out = {}
    for sh in SHUTTERS:
        m = evaluate([e.truth for e in sets[subset(speed, sh)].images], dets[sh])
        out[sh] = {k: round(float(m[k]), 6) for k in keep}
    m = evaluate([e.truth for sh in SHUTTERS for e in sets[subset(speed, sh)].images], dets["gs"] + dets["rs"])
    out["gsrs"] = {k: round(float(m[k]), 6) for k in keep}
    return out


def run_study(s: StudySettings, out: str | Path, *, workers: int = 1, executor: str | None = None,
              progress: bool | None = None, command: str | None = None) -> dict[str, Any]:
    """Build the datasets, run every job, write ``OUT/report.md``, ``report.json`` and the charts."""
    from ..datasets.build import build_dataset
    from ..datasets.executors import open_executor
    from ..progress import Progress

    root = output_dir(Path(out).resolve())  # a file there: one line, exit 2
    t0 = time.monotonic()
    for name, cfg in dataset_configs(s).items():
        build_dataset(cfg, root / "data" / name, workers=workers, progress=progress)
    t_data = time.monotonic() - t0
    jobs = plan_jobs(s)
    ex = open_executor(executor, workers, 1)
    bar = Progress(len(jobs), label=f"study {s.name}", enabled=progress, unit="run")
    results = []
    try:
        for doc in ex.map_unordered(functools.partial(run_job, s=s, root=str(root)), jobs):
            results.append(doc)
            bar.update(len(results))
            bar.status(f"last {doc['job']['key']}")
    finally:
        bar.close()
        ex.close()
    if len(results) != len(jobs):
        raise ConfigError(f"study: {len(jobs) - len(results)} run(s) gave no result")
    timing = {"datasets_s": round(t_data, 1), "total_s": round(time.monotonic() - t0, 1), "workers": workers,
              "train_s_sum": round(sum(r["train_s"] for r in results), 1)}
    return write_report(root, s, results, timing, command)
