"""In-sensor detections of a rollcam dataset, as they come off the emulated camera (``--detector insensor:NET``).

A rollcam dataset's records keep the ``emu:`` URI that reproduces each image (``records/<speed>/<name>.json``),
and the emulated camera is deterministic, so ``rollcam eval DATASET --detector insensor:NET`` does not run NET
on the stored files: for each image it opens the record's camera with ``insensor=NET`` (metadata-only, the
image's own shutter), reads its frame and the next one, and takes the result the next frame carries for it
(``rollcam.firmware.insensor_stage``). So the same evaluation scores the host pipeline (``--detector NET`` on
the stored pictures or mosaics) and the in-sensor one (what the device sends), image by image.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

from rollcam.common.errors import ConfigError

from .loaders import EvalSet
from .metrics import Dets

SHUTTER_OF = {"gs": "global", "rs": "rolling"}


def _record(root: Path, name: str) -> dict:
    hits = sorted(root.glob(f"records/*/{name}.json"))
    if not hits:
        raise ConfigError(f"dataset {str(root)!r} has no record of image {name!r} (records/*/{name}.json): "
                          "--detector insensor:NET needs a rollcam dataset")
    return json.loads(hits[0].read_text())


def insensor_detections(root: str | Path, s: EvalSet, network: str,
                        on_image: Callable[[], None] | None = None) -> list[Dets]:
    """The in-sensor network ``network``'s detections of every image of ``s`` (see the module docstring)."""
    from ..sources import open_camera

    root = Path(root)
    if s.shutter not in SHUTTER_OF:
        raise ConfigError(f"set {s.name!r} has no shutter (gs or rs): --detector insensor:NET needs a rollcam dataset")
    out = []
    for e in s.images:
        rec = _record(root, Path(e.key).stem)
        uri = f"{rec['uri']}&shutter={SHUTTER_OF[s.shutter]}&insensor={network}&insensor_output=meta&frames=2"
        with open_camera(uri) as cam:
            first, second = cam.read(), cam.read()
        got = [r for r in (second.insensor or ()) if r.seq == first.sequence]
        if not got:
            raise ConfigError(f"the camera of {e.key!r} sent no in-sensor result for its frame")
        r = got[0]
        out.append(Dets.of(r.boxes, r.scores, r.classes))
        if on_image is not None:
            on_image()
    return out
