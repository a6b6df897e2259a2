"""The study's baseline pipeline at evaluation time: the RS test images of a rollcam dataset gyro-corrected.

``rollcam eval DATASET --correct gyro`` adds two sets per speed beside GS and RS, from the same images:

- ``<speed>_rs_gsbox``: the RS images judged against the GS labels (each person's box at the frame's
  reference instant, what a GS image shows and what a correction aims at), the fair baseline for
- ``<speed>_rs_gyro``: the RS images corrected from the gyro (``rollcam.host.correction.gyro.correct_stored``: per-line
  rotational unwarp to the first line's orientation, from the IMU block the dataset keeps in each sample's
  record) and judged against the GS labels too.

So ``RS -> RS_GSBOX`` is what the skew costs a detector whose boxes are used as "where things are now" and
``RS_GSBOX -> RS_GYRO`` what the ISP's correction gives back: most of it under camera rotation, nothing under
object motion alone. A dataset records IMU blocks when built from a source with an IMU (``rollcam dataset
--source-options imu=on``); images stored as raw mosaics are not corrected (the ISP corrects processed images).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError

from .loaders import EvalSet, ImageEntry

EVAL_CORRECTIONS = ("gyro",)
"""What ``rollcam eval --correct`` can apply to a dataset's stored images. Flow correction needs the frame
before each one, which a dataset of single GS/RS pairs does not hold: it is measured by ``rollcam bench imu``
and runs live with ``rollcam detect --correct flow``."""


def _record(root: Path, tag: str, stem: str) -> dict[str, Any]:
    path = root / "records" / tag / f"{stem}.json"
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ConfigError(f"cannot read the sample record {str(path)!r} ({exc})") from None


def _gyro(rec: dict[str, Any], image: np.ndarray) -> np.ndarray:
    from ..correction.gyro import correct_stored, line_times

    img = rec["images"]["rs"]
    by_column = img["readout"] in ("left_to_right", "right_to_left")
    n = image.shape[1] if by_column else image.shape[0]
    return correct_stored(image, rec["imu"], line_times(*img["line_times_ns"], n), by_column=by_column)


def corrected_sets(root: str | Path, sets: list[EvalSet], method: str) -> list[EvalSet]:
    """``sets`` (a rollcam dataset's, one split) with the two sets per speed the module docstring describes."""
    if method not in EVAL_CORRECTIONS:
        raise ConfigError(f"--correct {method!r}: rollcam eval corrects with {list(EVAL_CORRECTIONS)} (flow needs "
                          "each image's previous frame, which a dataset does not keep; see rollcam bench imu)")
    root = Path(root)
    if not (root / "dataset.json").is_file():
        raise ConfigError(f"--correct needs a rollcam dataset folder (with records), got {str(root)!r}")
    card = json.loads((root / "dataset.json").read_text())
    if card.get("config", {}).get("raw_format"):
        raise ConfigError(f"dataset {str(root)!r} stores raw mosaics; --correct works on processed images")
    by = {(s.speed, s.shutter): s for s in sets}
    out = list(sets)
    for (speed, shutter), rs in by.items():
        gs = by.get((speed, "gs"))
        if shutter != "rs" or gs is None:
            continue
        tag = rs.name.rsplit("_", 1)[0]
        gs_truth = {Path(e.key).name: e.truth for e in gs.images}
        view, fixed = [], []
        for e in rs.images:
            name = Path(e.key).name
            rec = _record(root, tag, Path(name).stem)
            if "imu" not in rec:
                raise ConfigError(f"sample {rec.get('name')!r} of {str(root)!r} has no IMU block: build the dataset "
                                  "from a source with an IMU (rollcam dataset --source-options imu=on)")
            truth = gs_truth[name]
            view.append(ImageEntry(e.key, e.path, e.image_id, truth))
            prepare: Callable[[np.ndarray], np.ndarray] = partial(_gyro, rec)
            fixed.append(ImageEntry(f"{tag}_rs_{method}/{e.key.split('/', 1)[1]}", e.path, e.image_id, truth,
                                    prepare=prepare))
        out.append(EvalSet(f"{tag}_rs_gsbox", view, rs.class_names, speed, "rs_gsbox", same_images_as=rs.name))
        out.append(EvalSet(f"{tag}_rs_{method}", fixed, rs.class_names, speed, f"rs_{method}"))
    return out
