"""``rollcam study``: the study's experiments end to end: build the datasets, train every model, test each one.

The experiments (``plan_jobs``), each a set of training runs with ``seeds`` seeds where a difference is a
headline one:

- ``t1``: one model per subset (normal/fast x GS/RS), tested on the GS and RS test splits of its speed; its
  diagonal is the study's Table 1, its off-diagonal and GS+RS cells Table 3 (train GS / test RS and so on);
- ``t3``: models trained on GS and RS together, the missing cells of Table 3;
- ``speed``: GS and RS models at more walker speeds (1x, 5x, 10x, 20x): the RS penalty against speed;
- ``raw``: GS and RS models on the raw mosaic (ISP-less input), the same comparison without an ISP;
- ``fig4``: one RS subset trained on fewer scenes and fewer camera views (the study's Fig. 4);
- ``labels``: the label arm (``rollcam.host.training.labels``): RS models of ``label_speeds`` trained and tested
  with GS labels and with hand-like labels, beside ``t1``'s RS models (exact labels) and GS models;
- ``coco`` (no training): the COCO-trained detectors rollcam ships, not fine-tuned, on the four subsets (the
  study's Table 2).

A setting with a base (``base_frames``) first trains one model on GS images of scenes of another dataset seed
(``runs/base/``) and starts every other run from it: the study fine-tuned COCO-pretrained models.

Every run is an ordinary ``rollcam train`` folder under ``OUT/runs/`` with its test results beside it
(``test.json``): a rerun of the study resumes an interrupted run and skips finished ones. Runs go to the
dataset builder's executors (``--workers N`` processes, one torch thread each, or a Dask cluster).

A study longer than one machine's stay goes on elsewhere from its report alone (``adopt``): ``report.json``
holds every finished run's results and the digests of the datasets they were tested on, and ``base.pt`` beside
it the base model's weights, so another machine re-renders the same datasets (checked byte for byte), takes the
finished runs over and trains only the rest.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.common.files import output_dir, write_atomic

from .labels import ANNOTATOR, box_stats, relabel
from .study_report import write_report
from .study_settings import EXPERIMENTS, LABEL_ARMS, SHUTTERS, StudySettings, subset


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
    labels: str = "exact"


def plan_jobs(s: StudySettings, only: tuple[str, ...] = ()) -> list[Job]:
    """Every training run of the study, each once (an experiment that needs a run another has made shares it),
    seed by seed; ``only``: the runs of those experiments (the label arm brings the GS and exact-label RS runs of its
    speeds)."""
    jobs = _all_jobs(s)
    if only:
        bad = [g for g in only if g not in EXPERIMENTS]
        if bad:
            raise ConfigError(f"--only {bad[0]!r} is not one of {list(EXPERIMENTS)}")
        jobs = [j for j in jobs if j.group in only or ("labels" in only and j.group in ("t1", "speed")
                                                        and j.speed in s.label_speeds)]
    # seed-major: every run of seed 0 before any of seed 1, so a study cut short (or read half-way with
    # --report) holds every comparison at fewer seeds rather than some comparisons at all seeds
    return sorted(jobs, key=lambda j: j.seed)


def _all_jobs(s: StudySettings) -> list[Job]:
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
    for speed in s.label_speeds:
        for arm in LABEL_ARMS[1:]:
            jobs += [Job(f"{subset(speed, 'rs')}_{arm}labels_s{seed}", "labels", speed, (subset(speed, "rs"),), seed,
                         labels=arm) for seed in s.seeds]
    return jobs


BASE_THREADS = 2
"""torch threads of the base run, which runs alone before the others (fixed, not ``--workers``: a thread count is
part of what a resumed run must match)."""


def base_job(s: StudySettings) -> Job | None:
    """The run every other starts from in a setting with a base (``runs/base``), or None."""
    return Job("base", "base", "normal", (subset("normal", "gs"),), 0) if s.base_frames else None


def dataset_configs(s: StudySettings) -> dict[str, Any]:
    """The study's datasets: ``rgb`` (every speed) and ``raw`` (the raw-mosaic speeds), same scenes and instants."""
    from ..datasets.plan import DatasetConfig

    rgb = DatasetConfig(size=s.size, scenes=s.scenes, cameras=s.cameras, times=s.times, speeds=s.speeds,
                        frames=s.frames_per_speed * len(s.speeds), pedestrians=s.pedestrians, seed=0,
                        split_fractions=s.split)
    out = {"rgb": rgb}
    if s.raw_speeds:
        out["raw"] = replace(rgb, speeds=s.raw_speeds, frames=s.frames_per_speed * len(s.raw_speeds),
                             raw_format="RGGB")
    if s.base_frames:
        out["base"] = replace(rgb, speeds=("normal",), frames=s.base_frames, scenes=s.base_scenes, seed=s.base_seed,
                              split_fractions=(0.8, 0.1, 0.1))
    return out


def run_job(job: Job, s: StudySettings, root: str, device: str = "auto", threads: int = 1) -> dict[str, Any]:
    """Train (or resume, or find finished) one run and test it; the result is also ``runs/KEY/test.json``."""
    from .config import TrainConfig
    from .trainer import train

    run_dir = Path(root) / "runs" / job.key
    done = run_dir / "test.json"
    if done.is_file():
        return json.loads(done.read_text())
    data = Path(root) / "data" / ("raw" if job.raw else "rgb")
    is_base = job.group == "base"
    init = str(Path(root) / "runs" / "base" / "last.pt") if s.base_frames and not is_base else None
    cfg = TrainConfig(dataset=str(Path(root) / "data" / "base") if is_base else str(data), subsets=job.train,
                      model=s.model, epochs=s.base_epochs if is_base else s.epochs, imgsz=s.size, batch=s.batch,
                      lr=s.base_lr if is_base else s.lr, seed=job.seed, input="raw" if job.raw else "rgb",
                      threads=threads, steps=s.steps, val_every=s.val_every, scenes=job.scenes,
                      cameras=job.cameras, labels=job.labels, init=init)
    t0 = time.monotonic()
    result = train(cfg, run_dir, device=device, progress=False)
    t1 = time.monotonic()
    tests = test_model(result.model_path, data, job.speed, job.labels)
    doc = {"job": asdict(job), "test": tests, "train_s": round(t1 - t0, 3), "test_s": round(time.monotonic() - t1, 3),
           "val": result.card.get("final")}
    write_atomic(done, (json.dumps(doc, indent=1) + "\n").encode())
    return doc


def test_model(model: Path | str, dataset: Path, speed: str, labels: str = "exact",
               also: tuple[str, ...] = ()) -> dict[str, Any]:
    """The model (a ``model.onnx``, or a detector spec) on the test splits of ``speed``: GS, RS, and GS and RS
    pooled (``gsrs``), the RS images labelled by the arm ``labels``; with another arm than ``exact``, also the RS
    images against exact labels (``rs_exact``), and against each arm of ``also`` (``rs_ARMlabels``). The GS and
    RS cells carry ``mAP50_95_se``, the standard error of their mAP@0.5:0.95 over the test images
    (``bootstrap_se``; the other arms' cells, which no difference is taken of, do not)."""
    from ..detectors import load_detector
    from ..evaluation.loaders import load_rollcam, run_detector

    exact = load_rollcam(dataset, "test")
    sets = {s.name: s for s in relabel(exact, labels)}
    spec = f"onnx:{model}?conf=0.01&threads=1" if str(model).endswith(".onnx") else str(model)
    det = load_detector(spec)
    try:
        dets = {sh: run_detector(det, sets[subset(speed, sh)]) for sh in SHUTTERS}
    finally:
        det.close()
    out = {}
    for sh in SHUTTERS:
        out[sh] = scores([e.truth for e in sets[subset(speed, sh)].images], dets[sh])
    out["gsrs"] = scores([e.truth for sh in SHUTTERS for e in sets[subset(speed, sh)].images],
                         dets["gs"] + dets["rs"], se=False)
    other = {arm: f"rs_{arm}labels" for arm in also if arm != labels}
    if labels != "exact":
        other["exact"] = "rs_exact"
    for arm, key in other.items():
        rs = {s.name: s for s in relabel(exact, arm)}[subset(speed, "rs")]
        out[key] = scores([e.truth for e in rs.images], dets["rs"], se=False)
    return out


BOOTSTRAP = 100
"""Resamples of the test images behind each ``mAP50_95_se``."""


def scores(truths: list[Any], dets: list[Any], se: bool = True) -> dict[str, Any]:
    """P, R, mAP50 and mAP50_95 (and its bootstrap standard error over the images when ``se``)."""
    from ..evaluation.metrics import evaluate

    m = evaluate(truths, dets)
    out = {k: round(float(m[k]), 6) for k in ("P", "R", "mAP50", "mAP50_95")}
    if se:
        out["mAP50_95_se"] = round(bootstrap_se(truths, dets, BOOTSTRAP, np.random.default_rng(0)), 6)
    return out


def bootstrap_se(truths: list[Any], dets: list[Any], n: int, rng: np.random.Generator) -> float:
    """The standard error of mAP@0.5:0.95 from sampling the test images: its spread over ``n`` resamples of the
    images with replacement (one model, one set of detections)."""
    from ..evaluation.metrics import coco_map

    k = len(truths)
    if k < 2:
        return 0.0
    vals = []
    for _ in range(n):
        idx = rng.integers(0, k, k)
        vals.append(coco_map([truths[i] for i in idx], [dets[i] for i in idx])["mAP50_95"])
    return float(np.std(vals, ddof=1))


BASE_WEIGHTS = "base.pt"
"""Beside the report of a setting with a base: the base model's weights (a bare state dict, exactly what every
run was fine-tuned from), so that the report folder alone carries the study on (``adopt``)."""


def dataset_digests(s: StudySettings, root: Path) -> dict[str, str]:
    """``content_digest`` of each of the study's datasets built under ``root/data`` (what its runs were tested
    on; the report records it, ``adopt`` checks it)."""
    from ..datasets.layout import content_digest
    from ..datasets.sample import read_records

    return {name: content_digest(read_records(root / "data" / name)) for name in dataset_configs(s)
            if (root / "data" / name / "dataset.json").is_file()}


def weights_digest(state: dict[str, Any]) -> str:
    """One SHA-256 over a state dict's tensors (names, shapes, dtypes, bytes): which base model a run started from."""
    h = hashlib.sha256()
    for name in sorted(state):
        v = state[name]
        h.update(f"{name} {tuple(v.shape)} {v.dtype}\n".encode())
        h.update(v.detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()


def _base_state(run: Path) -> dict[str, Any]:
    """The weights a fine-tune's ``--init`` loads from ``run/last.pt`` (a checkpoint's model, or a bare state
    dict)."""
    from .trainer import load_state

    state = load_state(run / "last.pt")
    return state.get("model", state)


def export_base(s: StudySettings, root: Path) -> str | None:
    """Write ``root/base.pt``, the finished base model's weights (those of ``runs/base/last.pt``, which every
    run's ``--init`` loads), beside the report; return their ``weights_digest``, or None without a finished
    base. Written afresh every time: a copied folder's file times prove nothing."""
    run = root / "runs" / "base"
    if not s.base_frames or not (run / "test.json").is_file() or not (run / "last.pt").is_file():
        return None
    from .trainer import save_state

    state = _base_state(run)
    save_state(root / BASE_WEIGHTS, state)
    return weights_digest(state)


def read_report(s: StudySettings, src: str | Path, root: Path) -> tuple[Path, dict[str, Any]]:
    """The study report ``--adopt`` names (a folder holding ``report.json``, or the file), checked to be a report
    of this setting and not ``root``'s own: the checks that need nothing rendered."""
    src = Path(src)
    path = (src / "report.json" if src.is_dir() else src).resolve()
    if path.parent == root.resolve():
        raise ConfigError(f"--adopt {str(src)!r} is --out itself; name the report of another copy of the study")
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ConfigError(f"--adopt {str(src)!r}: no readable study report there ({exc})") from None
    if not isinstance(doc, dict) or doc.get("kind") != "rollcam-study":
        raise ConfigError(f"--adopt {str(path)!r} is not a rollcam study report")
    theirs, ours = doc.get("settings", {}), json.loads(json.dumps(s.to_json()))  # tuples as JSON has them
    if theirs != ours:
        diff = [f"{k}: {theirs.get(k)!r} there, {ours.get(k)!r} here" for k in sorted(set(theirs) | set(ours))
                if theirs.get(k) != ours.get(k)]
        raise ConfigError(f"--adopt {str(path)!r} is a study of other settings ({'; '.join(diff[:4])}"
                          f"{'; ...' if len(diff) > 4 else ''})")
    return path, doc


def adopt(s: StudySettings, root: Path, src: str | Path) -> list[str]:
    """Take the finished runs of another copy of this study into ``root``, so they are not trained again: ``src``
    is a study folder or its report copied elsewhere (``report.json``, and ``base.pt`` for a setting with a base).
    It must be of the same setting (``read_report``); a run is taken only when the dataset it was tested on is
    built under ``root`` and byte-identical (``dataset_digests``; a run of a dataset not built here waits for a
    later adopt); a setting with a base needs the report's base weights, matching the digest it records and any
    base ``root`` finished itself. Runs ``root`` has finished are kept. Returns the keys of the runs taken."""
    path, doc = read_report(s, src, root)
    made, here = doc.get("datasets") or {}, dataset_digests(s, root)
    if not made:
        raise ConfigError(f"--adopt {str(path)!r} records no dataset digests, so its runs cannot be checked "
                          "against these datasets (rewrite it with this version: rollcam study ... --report)")
    for name, digest in made.items():
        if name in here and here[name] != digest:
            raise ConfigError(f"--adopt {str(path)!r}: its runs were tested on another {name!r} dataset than the "
                              f"one built here (content digest {digest[:12]} there, {here[name][:12]} here); "
                              "a study's runs must share their test images")
    base = base_job(s)
    known = {j.key for j in _all_jobs(s)} | ({base.key} if base else set())
    runs: dict[str, dict[str, Any]] = {}
    for run in doc.get("runs", []):
        key = run.get("job", {}).get("key") if isinstance(run, dict) else None
        if key not in known:
            raise ConfigError(f"--adopt {str(path)!r}: {key!r} is not a run of the {s.name!r} setting")
        runs[key] = run

    verified = {name for name, digest in made.items() if here.get(name) == digest}
    # a run is taken where the dataset it was tested on is verified (the base too is tested on rgb's test split)
    todo = [k for k in sorted(runs) if not (root / "runs" / k / "test.json").is_file()
            and ("raw" if runs[k]["job"].get("raw") else "rgb") in verified]
    weights = path.parent / BASE_WEIGHTS
    if base is not None and todo:
        _check_base(root, weights, doc.get("base_sha256"), path)
    for key in todo:
        dest = root / "runs" / key / "test.json"
        dest.parent.mkdir(parents=True, exist_ok=True)
        if base is not None and key == base.key:  # the weights every fine-tune's --init loads
            write_atomic(dest.parent / "last.pt", weights.read_bytes())
        write_atomic(dest, (json.dumps(runs[key], indent=1) + "\n").encode())
    if "rgb" in verified:
        for name, table in (doc.get("coco") or {}).items():
            dest = root / "coco" / f"{name}.json"
            if not dest.is_file() and name in {d.split("?", 1)[0] for d in s.coco_detectors}:
                dest.parent.mkdir(parents=True, exist_ok=True)
                table = {k: v for k, v in table.items() if k != "spec"}
                write_atomic(dest, (json.dumps(table, indent=1) + "\n").encode())
    return todo


def _check_base(root: Path, weights: Path, digest: str | None, path: Path) -> None:
    """Refuse runs fine-tuned from a base other than the report's (its ``base.pt`` must be the one its runs
    started from) or than the one ``root`` finished itself: runs from two bases are not one study."""
    if not digest or not weights.is_file():
        raise ConfigError(f"--adopt {str(path)!r}: its runs were fine-tuned from a base model, and the report does "
                          f"not carry it ({BASE_WEIGHTS} beside it, and its digest base_sha256 in it)")
    from .trainer import load_state

    state = load_state(weights)
    if weights_digest(state.get("model", state)) != digest:
        raise ConfigError(f"--adopt {str(path)!r}: the {BASE_WEIGHTS} beside it is not the base its runs were "
                          "fine-tuned from (its weights do not match the report's base_sha256)")
    mine = root / "runs" / "base"
    if (mine / "test.json").is_file() and weights_digest(_base_state(mine)) != digest:
        raise ConfigError(f"--adopt {str(path)!r}: its runs were fine-tuned from another base model than the one "
                          f"finished under {str(root)!r}; a study's runs must share their base")


def finished_runs(s: StudySettings, root: Path) -> list[dict[str, Any]]:
    """Every run of the setting's whole plan finished under ``root`` (what ``report.json`` carries, whatever
    ``--only`` the report was made with, so that adopting it loses nothing)."""
    base = base_job(s)
    return [json.loads(p.read_text()) for j in ([base] if base else []) + _all_jobs(s)
            if (p := root / "runs" / j.key / "test.json").is_file()]


def report_finished(s: StudySettings, out: str | Path, command: str | None = None,
                    only: tuple[str, ...] = (), adopt_from: tuple[str | Path, ...] = ()) -> dict[str, Any]:
    """The report of the runs of ``OUT`` that have finished (``runs/KEY/test.json``; with those of
    ``adopt_from`` taken over first), with how many are."""
    root = Path(out).resolve()
    if not (root / "data" / "rgb" / "dataset.json").is_file():
        adopting = (" (--adopt checks the runs it takes against datasets rendered here: run the study command "
                    "with --adopt, without --report, to render them)") if adopt_from else ""
        raise ConfigError(f"--report: {str(out)!r} holds no study of this setting yet (no data/rgb){adopting}")
    for src in adopt_from:
        adopt(s, root, src)
    jobs = plan_jobs(s, only)
    base = base_job(s)
    results = [json.loads(p.read_text()) for j in ([base] if base else []) + jobs
               if (p := root / "runs" / j.key / "test.json").is_file()]
    extra: dict[str, Any] = {"datasets": dataset_digests(s, root), "base_sha256": export_base(s, root)}
    if done := coco_table(s, root, make=False):  # Table 2 whenever it was made, so the report carries it on
        extra["coco"] = done
    if not only or "labels" in only:
        extra["labels"] = label_tables(s, root)
    timing = {"datasets_s": 0.0, "total_s": 0.0, "workers": 0, "device": "cpu",
              "train_s_sum": round(sum(r["train_s"] for r in results), 1),
              "finished": len(results), "planned": len(jobs) + (base is not None)}
    return write_report(root, s, results, timing, command, extra, finished_runs(s, root))


def coco_table(s: StudySettings, root: Path, make: bool = True) -> dict[str, Any]:
    """The study's Table 2 analogue: each of ``s.coco_detectors`` (COCO-trained, not fine-tuned) on the GS and RS
    test splits of normal and fast walkers, RS scored against every label arm; kept in ``coco/DETECTOR.json``.
    ``make=False``: only the detectors already done."""
    data = root / "data" / "rgb"
    out = {}
    for spec in s.coco_detectors:
        name = spec.split("?", 1)[0]
        path = root / "coco" / f"{name}.json"
        if path.is_file():
            out[name] = json.loads(path.read_text()) | {"spec": spec}
            continue
        if not make:
            continue
        doc: dict[str, Any] = {}
        for speed in ("normal", "fast"):
            if speed not in s.speeds:
                continue
            doc[speed] = test_model(spec, data, speed, also=LABEL_ARMS[1:])
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, (json.dumps(doc, indent=1) + "\n").encode())
        out[name] = doc | {"spec": spec}
    return out


def label_tables(s: StudySettings, root: Path) -> dict[str, Any]:
    """Per label arm and speed: box statistics of the RS train split (and of the GS one) beside the study's, and
    the *label ceiling*: the exact RS boxes, as if a perfect detector had drawn them, scored against the arm's
    test labels (what the labels alone cost in mAP); for the hand arm also ``hand_inset``, the exact boxes with
    the annotator's inset (a detector that learnt the bias, left with the scatter)."""
    from ..evaluation.loaders import load_rollcam
    from ..evaluation.metrics import Dets, evaluate

    data = root / "data" / "rgb"
    no_scatter = dataclasses.replace(ANNOTATOR, edge_sd=0.0)
    train = load_rollcam(data, "train")
    test = load_rollcam(data, "test")
    boxes: dict[str, Any] = {}
    ceiling: dict[str, Any] = {}
    for arm in LABEL_ARMS:
        tr = {x.name: x for x in relabel(train, arm)}
        te = {x.name: x for x in relabel(test, arm)}
        ex = {x.name: x for x in test}
        for speed in s.speeds:
            rs, gs = subset(speed, "rs"), subset(speed, "gs")
            boxes.setdefault(speed, {"gs_images": box_stats(tr[gs])})[arm] = box_stats(tr[rs])
            truths = [e.truth for e in te[rs].images]
            perfect = [Dets.of(e.truth.boxes[~e.truth.ignore], np.ones(int((~e.truth.ignore).sum())),
                               e.truth.classes[~e.truth.ignore]) for e in ex[rs].images]
            m = evaluate(truths, perfect)
            ceiling.setdefault(speed, {})[arm] = {k: round(float(m[k]), 6) for k in ("mAP50", "mAP50_95")}
            if arm == "hand":  # a detector that learnt the annotator's inset, and only its scatter is left
                mean = [Dets.of(no_scatter.draw(d.boxes, np.random.default_rng(0)), d.scores, d.classes)
                        for d in perfect]
                m = evaluate(truths, mean)
                ceiling[speed]["hand_inset"] = {k: round(float(m[k]), 6) for k in ("mAP50", "mAP50_95")}
    return {"boxes": boxes, "ceiling": ceiling}


def run_study(s: StudySettings, out: str | Path, *, workers: int = 1, executor: str | None = None,
              progress: bool | None = None, command: str | None = None, only: tuple[str, ...] = (),
              device: str = "auto", report_only: bool = False,
              adopt_from: tuple[str | Path, ...] = ()) -> dict[str, Any]:
    """Build the datasets, run every job (of the experiments ``only`` names, when given), write
    ``OUT/report.md``, ``report.json`` and the charts (and ``base.pt``, the base model's weights, for a setting
    with a base). ``device`` ``auto`` trains on a CUDA GPU when torch sees one (runs then go one at a time),
    else on the CPU. ``report_only``: train nothing, write the report of the runs already finished (where a long
    study stands). ``adopt_from``: study folders or copied reports whose finished runs are taken over rather
    than trained again (``adopt``)."""
    if report_only:
        return report_finished(s, out, command, only, adopt_from)
    from ..datasets.build import build_dataset
    from ..datasets.executors import open_executor
    from ..progress import Progress
    from .trainer import resolve_device

    root = output_dir(Path(out).resolve())  # a file there: one line, exit 2
    for src in adopt_from:  # what needs nothing rendered is checked before the hours of rendering
        read_report(s, src, root)
    jobs = plan_jobs(s, only)
    device = resolve_device(device)
    t0 = time.monotonic()
    for name, cfg in dataset_configs(s).items():
        if name == "raw" and not any(j.raw for j in jobs):
            continue
        build_dataset(cfg, root / "data" / name, workers=workers, progress=progress)
    t_data = time.monotonic() - t0
    for src in adopt_from:
        adopt(s, root, src)
    extra: dict[str, Any] = {"device": device, "datasets": dataset_digests(s, root)}
    if done := coco_table(s, root, make=not only or "coco" in only):  # done before: carried on in the report
        extra["coco"] = done
    if not only or "labels" in only:
        extra["labels"] = label_tables(s, root)
    results = []
    base = base_job(s)
    if base is not None:
        results.append(run_job(base, s, str(root), device, threads=BASE_THREADS))
    if device == "cuda":
        workers, executor = 1, None
    ex = open_executor(executor, workers, 1)
    bar = Progress(len(jobs), label=f"study {s.name}", enabled=progress, unit="run")
    try:
        for doc in ex.map_unordered(functools.partial(run_job, s=s, root=str(root), device=device), jobs):
            results.append(doc)
            bar.update(len(results) - (base is not None))
            bar.status(f"last {doc['job']['key']}")
    finally:
        bar.close()
        ex.close()
    if len(results) != len(jobs) + (base is not None):
        raise ConfigError(f"study: {len(jobs) + (base is not None) - len(results)} run(s) gave no result")
    extra["base_sha256"] = export_base(s, root)
    timing = {"datasets_s": round(t_data, 1), "total_s": round(time.monotonic() - t0, 1), "workers": workers,
              "train_s_sum": round(sum(r["train_s"] for r in results), 1), "device": device,
              "finished": len(results), "planned": len(results)}
    return write_report(root, s, results, timing, command, extra, finished_runs(s, root))
