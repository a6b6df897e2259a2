"""``evaluate_dataset``: load the sets, get detections (a detector, the emulated camera's in-sensor network
(``insensor:NET``, ``rollcam.host.evaluation.insensor``) or a file), compute the metrics."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from rollcam.common.errors import ConfigError

from .loaders import EvalSet, load_detections, load_sets, run_detector
from .metrics import Dets, evaluate
from .report import build_document


def _save(path: Path, sets: list[EvalSet], dets: list[list[Dets]]) -> None:
    from rollcam.common.files import write_atomic

    lines = []
    for s, ds in zip(sets, dets, strict=True):
        if s.same_images_as is not None:  # another set's images: their lines are written once
            continue
        for e, d in zip(s.images, ds, strict=True):
            # full precision (shortest round-trip repr): scored again, the file gives exactly the live numbers
            items = [{"box": [float(v) for v in b], "score": float(sc), "cls": int(c)}
                     for b, sc, c in zip(d.boxes, d.scores, d.classes, strict=True)]
            lines.append(json.dumps({"image": e.key, "detections": items}))
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, ("\n".join(lines) + "\n").encode())


def evaluate_dataset(dataset: str | Path, *, detector: str | None = None, detections: str | Path | None = None,
                     split: str = "test", subset: str | None = None, images: str | Path | None = None,
                     save_detections: str | Path | None = None, progress: bool | None = None,
                     correct: str | None = None) -> dict[str, Any]:
    """The evaluation document of ``rollcam eval`` (see ``report.build_document``); ``correct='gyro'`` adds the
    gyro-corrected RS sets (``corrected.corrected_sets``)."""
    from ..progress import Progress

    if (detector is None) == (detections is None):
        raise ConfigError("give exactly one of a detector spec or a detections file")
    sets = load_sets(dataset, split, images)
    if correct is not None:
        from .corrected import corrected_sets

        sets = corrected_sets(dataset, sets, correct)
    if subset is not None:
        sets = [s for s in sets if s.name == subset]
        if not sets:
            raise ConfigError(f"--subset {subset!r} is not in {str(dataset)!r}")
    t0 = time.perf_counter()
    if detector is not None and detector.startswith("insensor:"):  # what the emulated camera's network sends
        from .insensor import insensor_detections

        network = detector.removeprefix("insensor:")
        all_dets = [insensor_detections(dataset, s, network) for s in sets]
        if save_detections is not None:
            _save(Path(save_detections), sets, all_dets)
    elif detector is not None:
        from ..detectors import load_detector

        det = load_detector(detector)
        names = {s.name for s in sets}
        todo = sum(len(s.images) for s in sets if s.same_images_as not in names)
        bar = Progress(todo, label=f"eval {detector}", enabled=progress, unit="img")
        n = [0]

        def tick() -> None:
            n[0] += 1
            bar.update(n[0])

        try:
            by_name: dict[str, list[Dets]] = {}
            for s in sets:  # a set of another's images (listed after it) reuses its detections
                by_name[s.name] = (by_name[s.same_images_as] if s.same_images_as in by_name
                                   else run_detector(det, s, tick))
            all_dets = [by_name[s.name] for s in sets]
        finally:
            bar.close()
            det.close()
        if save_detections is not None:
            _save(Path(save_detections), sets, all_dets)
    else:
        all_dets = load_detections(detections, sets)
    t1 = time.perf_counter()
    rows = [{"name": s.name, "speed": s.speed, "shutter": s.shutter,
             "metrics": evaluate([e.truth for e in s.images], d)} for s, d in zip(sets, all_dets, strict=True)]
    t2 = time.perf_counter()
    meta = {"dataset": str(dataset), "detector": detector or f"file:{detections}", "split": split,
            "timing": {"inference_s": round(t1 - t0, 3), "metrics_s": round(t2 - t1, 4)}}
    if correct is not None:
        meta["correct"] = correct
    return build_document(rows, meta)
