"""The run card of a training run (``train.json`` for programs, ``README.md`` for people) and its curves PNG.

The card says what made the model: the dataset (its folder and its own config, seed included), the subsets
trained and validated on, the options, the seed, the code (rollcam version, git commit and whether the tree had
uncommitted changes, torch version), the timings, the per-epoch history and the command that rebuilds it.
"""

from __future__ import annotations

import json
import platform
import shlex
import subprocess
from pathlib import Path
from typing import Any

from rollcam.common.files import write_atomic, write_figure

from .background import DEFAULT_KINDS
from .config import TrainConfig
from .data import DatasetInfo
from .model import STRIDE, count_parameters

CARD_JSON = "train.json"
CARD_MD = "README.md"
CURVES = "curves.png"


def git_state() -> dict[str, Any]:
    """The git commit of the rollcam source tree this code runs from and whether it has local changes
    (``commit`` None when it is not a git checkout, e.g. an installed wheel)."""
    here = Path(__file__).resolve().parent
    try:
        commit = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True, text=True,
                                timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(here), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10, check=True).stdout.strip() != ""
    except (OSError, subprocess.SubprocessError):
        return {"commit": None, "dirty": None}
    return {"commit": commit, "dirty": dirty}


def rebuild_command(cfg: TrainConfig, out: Path) -> str:
    """The ``rollcam train`` command line that trains this run again."""
    args = ["rollcam", "train", cfg.dataset]
    args += [a for s in cfg.subsets for a in ("--subset", s)]
    args += [a for s in cfg.val_subsets for a in ("--val", s)]
    args += ["--model", cfg.model, "--epochs", str(cfg.epochs), "--imgsz", f"{cfg.imgsz[0]}x{cfg.imgsz[1]}",
             "--batch", str(cfg.batch), "--lr", f"{cfg.lr:g}", "--seed", str(cfg.seed), "--input", cfg.input,
             "--threads", str(cfg.threads)]
    if cfg.steps:
        args += ["--steps", str(cfg.steps)]
    args += [a for flag, v in (("--scenes", cfg.scenes), ("--cameras", cfg.cameras)) if v for a in (flag, str(v))]
    if cfg.val_every != 1:
        args += ["--val-every", str(cfg.val_every)]
    if cfg.ema:
        args += ["--ema", f"{cfg.ema:g}"]
    if cfg.labels != "exact":
        args += ["--labels", cfg.labels]
    if cfg.background:
        args += ["--background", f"{cfg.background:g}"]
    if cfg.background_kinds != DEFAULT_KINDS:
        args += ["--background-kinds", ",".join(cfg.background_kinds)]
    if cfg.init:
        args += ["--init", cfg.init]
    args += ["--out", str(out)]
    return shlex.join(args)


def write_card(out: Path, cfg: TrainConfig, info: DatasetInfo, subsets: tuple[str, ...],
               val_subsets: tuple[str, ...], net: Any, history: list[dict[str, Any]], *, device: str,
               resumed_after: int, seconds: float, argv: list[str] | None) -> dict[str, Any]:
    """Write ``train.json``, ``README.md`` and ``curves.png`` into ``out``; return the card."""
    import torch

    from ..datasets.build import rollcam_version

    vals = [h for h in history if "val" in h]
    card = {
        "kind": "rollcam-train", "format": 1, "config": cfg.to_json(),
        "dataset": {"path": cfg.dataset, "pairs": info.card.get("pairs"), "config": info.card.get("config")},
        "subsets": list(subsets), "val_subsets": list(val_subsets),
        "model": {"architecture": "rollcam PersonNet (anchor-free, CenterNet/TTFNet head)", "size": cfg.model,
                  "parameters": count_parameters(net), "stride": STRIDE, "input": cfg.input,
                  "imgsz": f"{cfg.imgsz[0]}x{cfg.imgsz[1]}", "file": "model.onnx"},
        "device": device, "threads": cfg.threads, "torch": torch.__version__, "python": platform.python_version(),
        "rollcam_version": rollcam_version(), "git": git_state(),
        "timings": {"train_s": round(sum(h["seconds"] for h in history), 3), "this_run_s": round(seconds, 3),
                    "epoch_s": [h["seconds"] for h in history], "resumed_after_epoch": resumed_after},
        "final": vals[-1]["val"] if vals else None, "best_epoch": _best(vals), "history": history,
        "command": rebuild_command(cfg, out), "argv": argv,
    }
    write_atomic(out / CARD_JSON, (json.dumps(card, indent=1) + "\n").encode())
    write_atomic(out / CARD_MD, card_markdown(card).encode())
    plot_curves(history, out / CURVES, f"{cfg.model} on {', '.join(subsets)}")
    return card


def _best(vals: list[dict[str, Any]]) -> int | None:
    if not vals:
        return None
    return max(vals, key=lambda h: h["val"]["mAP50_95"])["epoch"]


def card_markdown(card: dict[str, Any]) -> str:
    """The human-readable run card."""
    c, m, f = card["config"], card["model"], card["final"]
    git = card["git"]
    lines = [
        "# rollcam training run", "",
        f"Person detector `{m['architecture']}`, size `{m['size']}` ({m['parameters']:,} parameters), input "
        f"{m['input']} {m['imgsz']}, exported as `model.onnx` (use it as `--detector onnx:model.onnx`).", "",
        "## Data and options", "",
        f"- dataset `{card['dataset']['path']}` ({card['dataset']['pairs']} GS/RS pairs; its seed "
        f"{(card['dataset']['config'] or {}).get('seed')})",
        f"- trained on {', '.join(card['subsets'])}; validated on {', '.join(card['val_subsets'])}",
        f"- {c['epochs']} epochs, batch {c['batch']}, lr {c['lr']:g} (AdamW, cosine), seed {c['seed']}, "
        f"{c['threads']} thread(s) on {card['device']}" + (f", initialised from `{c['init']}`" if c["init"] else "")
        + (f"; exported the weights' moving average (decay {c['ema']:g})" if c.get("ema") else "")
        + (f"; RS images with {c['labels']} labels" if c.get("labels", "exact") != "exact" else "")
        + (f"; {c['background']:g} background image(s) per training image"
           + (f" ({', '.join(c['background_kinds'])} in turn)"
              if tuple(c.get("background_kinds", DEFAULT_KINDS)) != DEFAULT_KINDS else "")
           if c.get("background") else ""),
        f"- code: rollcam {card['rollcam_version']}, commit {git['commit'] or 'unknown'}"
        + (" (with local changes)" if git["dirty"] else "") + f", torch {card['torch']}", "",
        "## Result (validation split, scored through `onnx:`)", "",
    ]
    if f:
        lines += ["| P | R | mAP@0.5 | mAP@0.5:0.95 |", "|---:|---:|---:|---:|",
                  f"| {f['P']:.3f} | {f['R']:.3f} | {f['mAP50']:.3f} | {f['mAP50_95']:.3f} |", ""]
    lines += [f"Training time {card['timings']['train_s']:.1f} s over {len(card['history'])} epochs. "
              "Curves: `curves.png`.", "", "## Rebuild", "", "```sh norun", card["command"], "```", ""]
    return "\n".join(lines)


def plot_curves(history: list[dict[str, Any]], path: Path, title: str) -> None:
    """Training loss and validation mAP against epoch, side by side; written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.6))
    ep = [h["epoch"] for h in history]
    a.plot(ep, [h["loss"] for h in history], "o-", label="total")
    a.plot(ep, [h["heat"] for h in history], ".--", label="heatmap (focal)")
    a.plot(ep, [h["box"] for h in history], ".--", label="box (GIoU)")
    a.set_xlabel("epoch")
    a.set_ylabel("training loss")
    a.legend(fontsize=8)
    vals = [h for h in history if "val" in h]
    b.plot([h["epoch"] for h in vals], [h["val"]["mAP50"] for h in vals], "o-", label="mAP@0.5")
    b.plot([h["epoch"] for h in vals], [h["val"]["mAP50_95"] for h in vals], "s-", label="mAP@0.5:0.95")
    b.set_xlabel("epoch")
    b.set_ylabel("validation")
    b.set_ylim(0, 1)
    b.legend(fontsize=8)
    for ax in (a, b):
        ax.grid(alpha=0.3)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    write_figure(path, fig, dpi=100)
