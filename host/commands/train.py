"""``rollcam train``: train rollcam's person detector on a rollcam dataset and export it as ONNX."""

from __future__ import annotations

import argparse
import json
import os

from rollcam.common.values import fraction, parse_size, positive_float, positive_int

from ..training.study_settings import LABEL_ARMS
from . import Subparsers, value_type

DESCRIPTION = """\
Train rollcam's own small anchor-free person detector (plain PyTorch, MIT; needs the 'train' extra,
rollcam[train]) from scratch on the chosen subsets of a rollcam dataset, or fine-tune it from a
checkpoint (--init). Every epoch writes DIR/last.pt atomically: interrupt the run and rerun the same command to
continue. Deterministic for a seed and --threads on CPU. Writes DIR/model.onnx (read by
--detector onnx:DIR/model.onnx in rollcam eval and rollcam detect), the loss and validation-mAP curves
DIR/curves.png and a run card DIR/train.json + DIR/README.md."""

EPILOG = """\
examples:
  rollcam train data/letsroll --subset normal_rs --out runs/normal_rs
  rollcam train data/letsroll --subset normal_gs --subset normal_rs --val normal_rs --epochs 40 --out runs/both
  rollcam eval data/letsroll --detector 'onnx:runs/normal_rs/model.onnx?conf=0.05'"""

_COUNT = value_type(positive_int, "an integer >= 1")


def _kinds(text: str) -> tuple[str, ...]:
    """``--background-kinds``: a comma-separated cycle of background kinds."""
    from ..training.background import check_kinds

    return check_kinds(tuple(k.strip() for k in text.split(",") if k.strip()), option="")


def add_parser(sub: Subparsers) -> argparse.ArgumentParser:
    """Add ``rollcam train``."""
    p = sub.add_parser("train", help="train a person detector on a rollcam dataset and export ONNX",
                       description=DESCRIPTION, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dataset", metavar="DATASET", help="rollcam dataset folder (from 'rollcam dataset')")
    p.add_argument("--subset", action="append", default=[], metavar="NAME",
                   help="train on this subset (repeat to combine; default: every subset), e.g. normal_rs")
    p.add_argument("--val", action="append", default=[], metavar="NAME",
                   help="validate on this subset's val split (repeat; default: the training subsets)")
    p.add_argument("--model", default="nano", help="model size: pico, nano, small (default: %(default)s)")
    p.add_argument("--epochs", type=_COUNT, default=30, metavar="N", help="epochs (default: %(default)s)")
    p.add_argument("--steps", type=_COUNT, default=None, metavar="N",
                   help="at most N optimiser steps per epoch (default: the whole training split)")
    p.add_argument("--imgsz", type=value_type(parse_size), default=(640, 360), metavar="WxH",
                   help="network input; frames are letterboxed to it (default: 640x360)")
    p.add_argument("--batch", type=_COUNT, default=16, metavar="N", help="images per step (default: %(default)s)")
    p.add_argument("--lr", type=value_type(positive_float, "a number > 0"), default=2e-3,
                   help="peak learning rate (default: %(default)s)")
    p.add_argument("--seed", type=value_type(int, "an integer"), default=0, help="training seed (default: 0)")
    p.add_argument("--input", choices=("rgb", "raw"), default="rgb",
                   help="rgb pictures, or the raw mosaic of a dataset built with --raw (ISP-less; default: rgb)")
    p.add_argument("--init", default=None, metavar="CKPT", help="start from these weights: a last.pt, a state dict "
                   "or a model.onnx written by rollcam train (the shipped personnet's too), of the same model size")
    p.add_argument("--threads", type=_COUNT, default=None, metavar="N",
                   help="torch threads; part of what makes a run reproducible (default: min(8, cores))")
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto",
                   help="auto: a CUDA GPU when torch sees one, else the CPU (default: auto)")
    p.add_argument("--scenes", type=_COUNT, default=None, metavar="N",
                   help="train on the images of the first N training scenes only (default: all)")
    p.add_argument("--cameras", type=_COUNT, default=None, metavar="N",
                   help="train on camera views 0..N-1 only (default: all)")
    p.add_argument("--ema", type=value_type(fraction, "a number in [0, 1)"), default=0.0, metavar="DECAY",
                   help="validate and export an exponential moving average of the weights with this decay, "
                        "e.g. 0.999 (default: 0, off)")
    p.add_argument("--labels", choices=LABEL_ARMS, default="exact",
                   help="boxes of the RS images: exact (rollcam's RS box), gs (the box at the reference instant, "
                        "from the GS image of the pair) or hand (a modelled annotator's; docs/training.md) "
                        "(default: %(default)s)")
    p.add_argument("--background", type=value_type(fraction, "a number in [0, 1]"), default=0.0, metavar="F",
                   help="add F background images (no person: flat frames, crops of person-free regions, empty "
                        "streets) per training image, e.g. 0.1, so the model learns what no person looks like "
                        "(default: 0, none)")
    p.add_argument("--background-kinds", type=value_type(_kinds), default=None, metavar="KIND[,KIND]",
                   help="the cycle of background kinds: flat, crop (person-free regions), street (empty streets), "
                        "edge (person-free bands cropped flush with a frame edge); a kind named twice comes twice "
                        "as often (default: flat,crop,street)")
    p.add_argument("--val-every", type=_COUNT, default=1, metavar="N", help="validate every N epochs (default: 1)")
    p.add_argument("--out", required=True, metavar="DIR", help="run folder (rerun to resume)")
    p.add_argument("--json", action="store_true", help="print the run card as JSON on stdout")
    p.add_argument("--progress", action="store_true", help="show progress even when stderr is not a terminal")
    return p


def config_from_args(args: argparse.Namespace):
    """The TrainConfig the options describe."""
    from ..training.background import DEFAULT_KINDS
    from ..training.config import TrainConfig

    return TrainConfig(dataset=args.dataset, subsets=tuple(args.subset), val_subsets=tuple(args.val),
                       model=args.model, epochs=args.epochs, imgsz=args.imgsz, batch=args.batch, lr=args.lr,
                       seed=args.seed, input=args.input, init=args.init,
                       threads=args.threads or min(8, os.cpu_count() or 1), steps=args.steps,
                       val_every=args.val_every, scenes=args.scenes, cameras=args.cameras, ema=args.ema,
                       labels=args.labels, background=args.background,
                       background_kinds=args.background_kinds or DEFAULT_KINDS)


def run(args: argparse.Namespace) -> int:
    """Train (or resume), export, and print where the model and its card are."""
    from ..training.trainer import train

    cfg = config_from_args(args)
    result = train(cfg, args.out, device=args.device, progress=True if args.progress else None,
                   argv=getattr(args, "argv", None))
    if args.json:
        print(json.dumps(result.card))
        return 0
    final = result.card.get("final") or {}
    resumed = f" (resumed after epoch {result.resumed_after})" if result.resumed_after else ""
    print(f"train: {result.epochs} epochs{resumed} in {result.card['timings']['train_s']:.1f} s; validation "
          f"P {final.get('P', 0):.3f} R {final.get('R', 0):.3f} mAP50 {final.get('mAP50', 0):.3f} "
          f"mAP50-95 {final.get('mAP50_95', 0):.3f}")
    print(f"model: {result.model_path} (use --detector onnx:{result.model_path}); card {result.out_dir / 'README.md'}")
    return 0
