"""Measure a ``rollcam train --input raw`` run and copy it into the package as the ``personnet-raw`` detector.

    python tools/ship_personnet_raw.py RUN DATASET [DEST]

RUN is the training folder (``model.onnx``, ``train.json``), DATASET the raw rollcam dataset it was trained on
(val and test splits), DEST the package folder (default ``host/detectors/models/personnet_raw``). Measures, in
this one run: the score threshold of best F1 on the validation split (the mean of the subsets' best-F1
thresholds), ``rollcam eval``'s table on the test split (at ``conf=0.01``), the model's multiply-accumulates
per run (from its graph) and its median and fastest time per run on one CPU thread. Writes
DEST/model.onnx, DEST/personnet_raw.json (figures + training card), DEST/README.md and DEST/LICENSE.
``tools/train_personnet_raw.sh`` runs the whole chain.
"""

from __future__ import annotations

import hashlib
import json
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ship_personnet import write_package  # the same package layout and MIT grant as personnet's


def measure(run: Path, data: Path) -> dict[str, Any]:
    """The figures of the card (see the module docstring)."""
    import numpy as np
    from rollcam.host.detectors import load_detector
    from rollcam.host.detectors.onchip import onnx_macs
    from rollcam.host.evaluation.run import evaluate_dataset

    model = run / "model.onnx"
    spec = f"onnx:{model}?conf=0.01"
    val = evaluate_dataset(data, detector=spec, split="val")["results"]
    confs = [m["conf"] for per in val.values() for k, m in per.items() if k in ("gs", "rs")]
    test = evaluate_dataset(data, detector=spec, split="test")["results"]
    det = load_detector(f"onnx:{model}?threads=1")
    image = np.zeros((det.height, det.width), np.uint8)
    det.detect(image)
    times = []
    for _ in range(30):
        t0 = time.perf_counter()
        det.detect(image)
        times.append((time.perf_counter() - t0) * 1e3)
    blob = model.read_bytes()
    return {"file_mb": round(len(blob) / 1e6, 3), "sha256": hashlib.sha256(blob).hexdigest(),
            "conf": round(float(np.mean(confs)), 4), "val": val, "test": test,
            "macs": onnx_macs(str(model), det.width, det.height), "input": [det.width, det.height],
            "ms_detect": round(float(np.median(times)), 2), "ms_detect_min": round(float(np.min(times)), 2)}


def readme(fig: dict[str, Any], train: dict[str, Any]) -> str:
    """The people's card."""
    cfg, ds = train["config"], train["dataset"]
    rows = [f"| {speed} {sh.upper()} | {m['images']} | {m['boxes']} | {m['P']:.3f} | {m['R']:.3f} | "
            f"{m['mAP50']:.3f} | {m['mAP50_95']:.3f} |"
            for speed, per in fig["test"].items() for sh, m in per.items() if sh in ("gs", "rs")]
    return "\n".join([
        "# personnet-raw: rollcam's person detector on the raw Bayer mosaic (ONNX)", "",
        "`model.onnx` is rollcam's anchor-free PersonNet (docs/training.md) trained from scratch by",
        "`rollcam train --input raw` on the 8-bit RGGB mosaics of rollcam's own study camera (no ISP: what the",
        "sensor's pixels give), both shutters together. It is the emulated camera's default in-sensor network",
        "(docs/insensor.md). Licence: MIT (`LICENSE`): rollcam's code and synthetic data, no third-party weights.", "",
        f"- Model: `{cfg['model']}`, input [1, 1, {fig['input'][1]}, {fig['input'][0]}] mosaic 0..1 (letterboxed), "
        f"{fig['macs']:,} multiply-accumulates per run; {fig['file_mb']} MB, SHA-256 `{fig['sha256']}`.",
        f"- Data: `{ds['path']}`, {ds['pairs']} GS/RS pairs, {ds['config']['size']}, speeds "
        f"{', '.join(ds['config']['speeds'])}; trained on the train split of {', '.join(train['subsets'])}.",
        f"- Schedule: {cfg['epochs']} epochs, batch {cfg['batch']}, lr {cfg['lr']:g}, seed {cfg['seed']}, "
        f"{cfg['threads']} thread(s) on a shared 2-core machine: {train['timings']['train_s']:.0f} s.",
        f"- Default threshold `conf={fig['conf']}`: best F1 on the validation split.",
        f"- Time per run on one CPU thread here: median {fig['ms_detect']} ms, fastest {fig['ms_detect_min']} ms.",
        "", "A small model on a small dataset: its figures are modest, and are what it is.", "",
        "Test split (P and R at best F1; mAP at `conf=0.01`):", "",
        "| test set | images | boxes | P | R | mAP@0.5 | mAP@0.5:0.95 |", "|---|---:|---:|---:|---:|---:|---:|",
        *rows, "", "## Rebuild", "", "```sh norun", "tools/train_personnet_raw.sh", "```", "",
        f"Trained from rollcam commit `{train['git']['commit']}` with `{train['command']}`.", ""])


def main(argv: list[str]) -> int:
    if len(argv) not in (2, 3):
        print(__doc__, file=sys.stderr)
        return 2
    run, data = Path(argv[0]), Path(argv[1])
    dest = Path(argv[2]) if len(argv) == 3 else Path("host/detectors/models/personnet_raw")
    fig = measure(run, data)
    train = json.loads((run / "train.json").read_text())
    write_package(run, dest, "personnet-raw", fig, train, readme(fig, train))
    print(f"shipped {run / 'model.onnx'} -> {dest}: conf {fig['conf']}, {fig['macs']:,} MACs")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
