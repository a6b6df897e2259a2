"""Copy a trained PersonNet run into the package as the ``personnet`` detector, with its cards and licence.

    python tools/ship_personnet.py RUN BENCH_JSON [DEST]

RUN is a ``rollcam train`` folder (``model.onnx``, ``train.json``), BENCH_JSON the document ``rollcam bench
personnet --model RUN/model.onnx --dataset DATA`` wrote for it, DEST the package folder (default
``host/detectors/models/personnet``). Writes DEST/model.onnx, DEST/personnet.json (figures + training card),
DEST/README.md (the card for people) and DEST/LICENSE. A run fine-tuned from another (``--init
OTHER/model.onnx`` or ``OTHER/last.pt``) carries OTHER's card along as its earlier stage, while OTHER is still there.
``tools/train_personnet.sh`` runs the whole chain.
"""

from __future__ import annotations

import hashlib
import json
import shlex
import shutil
import sys
from pathlib import Path
from typing import Any

from rollcam.host.training.background import DEFAULT_KINDS

LICENSE = """\
MIT License

Copyright (c) 2026 the rollcam authors

The weights in model.onnx were trained from scratch by rollcam's own trainer (rollcam train, plain PyTorch)
on synthetic images rendered by rollcam itself (rollcam dataset); no third-party data, weights or code went
into them. They are part of rollcam and under its licence:

Permission is hereby granted, free of charge, to any person obtaining a copy of this software and associated
documentation files (the "Software"), to deal in the Software without restriction, including without
limitation the rights to use, copy, modify, merge, publish, distribute, sublicense, and/or sell copies of the
Software, and to permit persons to whom the Software is furnished to do so, subject to the following
conditions:

The above copyright notice and this permission notice shall be included in all copies or substantial portions
of the Software.

THE SOFTWARE IS PROVIDED "AS IS", WITHOUT WARRANTY OF ANY KIND, EXPRESS OR IMPLIED, INCLUDING BUT NOT LIMITED
TO THE WARRANTIES OF MERCHANTABILITY, FITNESS FOR A PARTICULAR PURPOSE AND NONINFRINGEMENT. IN NO EVENT SHALL
THE AUTHORS OR COPYRIGHT HOLDERS BE LIABLE FOR ANY CLAIM, DAMAGES OR OTHER LIABILITY, WHETHER IN AN ACTION OF
CONTRACT, TORT OR OTHERWISE, ARISING FROM, OUT OF OR IN CONNECTION WITH THE SOFTWARE OR THE USE OR OTHER
DEALINGS IN THE SOFTWARE.
"""


def _row(name: str, m: dict[str, Any]) -> str:
    return (f"| {name} | {m['images']} | {m['boxes']} | {m['P']:.3f} | {m['R']:.3f} | {m['mAP50']:.3f} | "
            f"{m['mAP50_95']:.3f} |")


def stages(train: dict[str, Any]) -> list[dict[str, Any]]:
    """The run's training cards, first stage first: a run fine-tuned with ``--init DIR/model.onnx`` (or
    ``DIR/last.pt``) is preceded by the card in DIR, when that run is still there."""
    chain = [train]
    while chain[0]["config"].get("init"):
        before = Path(chain[0]["config"]["init"]).parent / "train.json"
        if not before.is_file():
            break
        chain.insert(0, json.loads(before.read_text()))
    return chain


def _data_line(card: dict[str, Any]) -> str:
    ds = card["dataset"]
    return (f"`{ds['path']}`, {ds['pairs']} GS/RS pairs at 1920x1080 ({ds['config']['scenes']} scenes x "
            f"{ds['config']['cameras']} cameras x {len(ds['config']['times'])} times of day, speeds "
            f"{', '.join(ds['config']['speeds'])}, dataset seed {ds['config']['seed']}); the train split of "
            f"{', '.join(card['subsets'])}")


def _schedule_line(card: dict[str, Any]) -> str:
    cfg = card["config"]
    steps = f" of at most {cfg['steps']} steps" if cfg.get("steps") else ""
    start = f"from `{cfg['init']}`" if cfg.get("init") else "from scratch"
    ema = f", exporting the weights' moving average (decay {cfg['ema']:g})" if cfg.get("ema") else ""
    kinds = cfg.get("background_kinds")
    bg = (f", with {cfg['background']:g} background image(s) (no person) per training image"
          + (f" ({', '.join(kinds)} in turn)" if kinds and tuple(kinds) != DEFAULT_KINDS else "")
          if cfg.get("background") else "")
    return (f"{cfg['epochs']} epochs{steps}, batch {cfg['batch']}, AdamW lr {cfg['lr']:g} (warm-up, cosine), "
            f"seed {cfg['seed']}, {cfg['threads']} thread(s) on {card['device']}, {start}{ema}{bg}: "
            f"{card['timings']['train_s']:.0f} s")


def _dataset_command(card: dict[str, Any]) -> str:
    ds = card["dataset"]
    seed = ds["config"].get("seed", 0)
    return (f"rollcam dataset --out {ds['path']} --frames {ds['pairs']} --scenes {ds['config']['scenes']} "
            + (f"--seed {seed} " if seed else "") + "--workers 2")


def readme(fig: dict[str, Any], train: dict[str, Any]) -> str:
    """The people's card: what the model is, how it was made, what it scores, and how to rebuild it."""
    cfg, chain = train["config"], stages(train)
    lines = [
        "# personnet: rollcam's own person detector (ONNX)", "",
        "`model.onnx` is rollcam's anchor-free PersonNet (docs/training.md) trained from scratch by `rollcam train`",
        "on rollcam's own paired global/rolling-shutter street renders (`rollcam dataset`), both walking speeds",
        "and both shutters together. Licence: MIT (`LICENSE`): rollcam's code, rollcam's synthetic data, no",
        "third-party weights. In rollcam it is the detector `personnet` (`--detector personnet`,",
        "`load_detector(\"personnet\")`); `personnet.json` holds the full training card and these figures.", "",
        f"- Model: `{cfg['model']}`, {train['model']['parameters']:,} parameters, input `images` "
        f"[1, 3, {cfg['imgsz'].split('x')[1]}, {cfg['imgsz'].split('x')[0]}] RGB 0..1 (letterboxed), output "
        "[1, 5, N] cx, cy, w, h, score (heatmap peaks; NMS in the detector).",
        f"- File: {fig['file_mb']} MB, SHA-256 `{fig['sha256']}`.",
    ]
    for i, card in enumerate(chain, 1):
        head = f"Stage {i} of {len(chain)}: data" if len(chain) > 1 else "Data"
        lines += [f"- {head} {_data_line(card)}.", f"  Schedule: {_schedule_line(card)}."]
    lines += [
        f"- Default NMS `iou={fig.get('iou', 0.45)}`: best mAP@0.5:0.95 on the validation split (the heatmap's peak "
        "pick already suppresses duplicates).",
        f"- Default threshold `conf={fig['conf']}`: best F1 on the validation split at that `iou`.", "",
        "## Figures (one run of `rollcam bench personnet`, on this project's shared 2-core machine)", "",
        f"- Time per 640x360 frame on one CPU core (onnxruntime, 1 thread): network {fig['ms_model']} ms, "
        f"`detect()` with letterbox and NMS {fig['ms_detect']} ms.",
        f"- Empty street frames (no pedestrians; {fig['empty']['frames']} frames, 1920x1080): "
        f"{fig['empty']['fp_per_frame']} false positives per frame at conf {fig['empty']['conf']} "
        f"({fig['empty']['frames_with_fp']} frames with any)."]
    if "flat" in fig:
        lines.append(f"- Featureless frames (flat black to white, clean and noisy; {fig['flat']['frames']} frames, "
                     f"1920x1080): {fig['flat']['fp_per_frame']} false positives per frame at conf "
                     f"{fig['flat']['conf']} ({fig['flat']['frames_with_fp']} frames with any; highest score "
                     f"{fig['flat']['max_score']}).")
    lines += [
        "",
        f"Test split of `{fig.get('dataset', train['dataset']['path'])}`, 1920x1080 frames scored at the model's "
        "input (P and R at best F1; mAP at `conf=0.01`; "
        f"NMS `iou={fig.get('iou', 0.45)}`):", "",
        "| test set | images | boxes | P | R | mAP@0.5 | mAP@0.5:0.95 |", "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for speed, per in fig["test"].items():
        lines += [_row(f"{speed} {sh.upper()}", per[sh]) for sh in ("gs", "rs") if sh in per]
    lines += [_row("all four", fig["pooled"]), "", "Targets:", ""]
    lines += [f"- {name}: {t['value']} {t['op']} {t['limit']}: {'met' if t['pass'] else 'not met'}"
              for name, t in fig["targets"].items()]
    for i, card in enumerate(chain, 1):
        stage = f", stage {i}" if len(chain) > 1 else ""
        lines += ["", f"Validation (all four subsets{stage}) by epoch:", "",
                  "| epoch | loss | val mAP@0.5 | val mAP@0.5:0.95 |", "|---:|---:|---:|---:|"]
        lines += [f"| {h['epoch']} | {h['loss']:.3f} | {h['val']['mAP50']:.3f} | {h['val']['mAP50_95']:.3f} |"
                  for h in card["history"] if "val" in h]
    lines += ["", "## Rebuild", "", "```sh norun", "tools/train_personnet.sh    # datasets, training, figures, "
              "and this folder", "```", "", "which runs:", "", "```sh norun"]
    for card in chain:
        lines += [_dataset_command(card), card["command"]]
    args = shlex.split(train["command"])
    run = args[args.index("--out") + 1]
    data = fig.get("dataset", train["dataset"]["path"])
    if data not in {card["dataset"]["path"] for card in chain}:  # a dataset of its own for the figures
        doc = json.loads((Path(data) / "dataset.json").read_text())
        lines.append(_dataset_command({"dataset": {"path": data, "pairs": doc["pairs"], "config": doc["config"]}}))
    scenes = fig["empty"]["frames"] // 15  # 5 cameras x 3 times of day a scene
    empty = f"--empty-scenes {scenes} " if scenes != 10 else ""
    lines += [f"rollcam bench personnet --model {run}/model.onnx --dataset {data} {empty}"
              "--out rollcam_out/personnet/bench",
              f"python tools/ship_personnet.py {run} rollcam_out/personnet/bench/personnet.json",
              "```", "", f"Trained from rollcam commit `{train['git']['commit']}`.", ""]
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    if len(argv) not in (2, 3):
        print(__doc__, file=sys.stderr)
        return 2
    run, bench = Path(argv[0]), Path(argv[1])
    dest = Path(argv[2]) if len(argv) == 3 else Path("host/detectors/models/personnet")
    fig = json.loads(bench.read_text())
    train = json.loads((run / "train.json").read_text())
    model = (run / "model.onnx").read_bytes()
    if hashlib.sha256(model).hexdigest() != fig["sha256"]:
        print(f"{bench} measured another model than {run / 'model.onnx'}", file=sys.stderr)
        return 2
    fig = {k: v for k, v in fig.items() if k != "model"}
    card = readme(fig, train)
    earlier = stages(train)[:-1]
    if earlier:  # the cards of the runs this one was fine-tuned from, first first
        train = {**train, "earlier_stages": earlier}
    write_package(run, dest, "personnet", fig, train, card)
    print(f"shipped {run / 'model.onnx'} -> {dest}")
    return 0


def write_package(run: Path, dest: Path, name: str, fig: dict[str, Any], train: dict[str, Any], card: str) -> None:
    """DEST/model.onnx, DEST/<name>.json (figures + training card), DEST/README.md and DEST/LICENSE."""
    dest.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(run / "model.onnx", dest / "model.onnx")
    (dest / f"{name.replace('-', '_')}.json").write_text(
        json.dumps({"name": name, "licence": "MIT", "figures": fig, "training": train}, indent=1) + "\n")
    (dest / "README.md").write_text(card)
    (dest / "LICENSE").write_text(LICENSE)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
