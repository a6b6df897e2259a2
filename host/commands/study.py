"""``rollcam study``: the study's experiments end to end (datasets, training, tests, report)."""

from __future__ import annotations

import argparse
import json
import shlex

from rollcam.common.values import positive_int

from ..training.study_settings import EXPERIMENTS
from . import Subparsers, value_type

DESCRIPTION = """\
Reproduce the study's experiments with rollcam's own detector: build (or reuse) paired GS/RS datasets, train
one model per subset and seed, test each on the GS, RS and pooled test splits, and write OUT/report.md,
OUT/report.json and OUT/report.png: the Table 1 and Table 3 analogues beside the study's numbers, the RS
penalty against walking speed (RGB and raw-mosaic input), accuracy against the number of training scenes and
camera views (Fig. 4), with mean, spread and a significance flag over the seeds. Settings: quick (CI-sized,
minutes), reduced (the CPU setting: within 2 hours on 2 cores with --workers 2), medium (640x360, nano
fine-tuned from a base model, sized to resolve a 5 % mAP@0.5:0.95 difference: hours of background CPU), full
(the study's design, for a GPU). The label arm trains and tests RS models with exact, GS and hand-like labels;
coco scores the shipped COCO-trained detectors (Table 2). Interrupt and rerun the same command: it resumes.
Needs the 'train' extra."""

EPILOG = """\
examples:
  rollcam study --quick --out rollcam_out/study_quick
  rollcam study --setting reduced --workers 2 --out rollcam_out/study_reduced
  rollcam study --setting reduced --only labels,coco --workers 2 --out rollcam_out/study_reduced
  nice -n 19 rollcam study --setting medium --workers 2 --out rollcam_out/study_medium   # hours; resumable
  rollcam study --setting full --out /data/study_full                      # on a GPU machine
  rollcam study --setting medium --workers 2 --out study_medium --adopt docs/study_medium   # go on from a report"""


def add_parser(sub: Subparsers) -> argparse.ArgumentParser:
    """Add ``rollcam study``."""
    p = sub.add_parser("study", help="the study's tables end to end: datasets, training, tests, report",
                       description=DESCRIPTION, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--setting", choices=("quick", "reduced", "medium", "full"), default="reduced",
                   help="experiment size (default: %(default)s)")
    p.add_argument("--quick", action="store_const", const="quick", dest="setting", help="same as --setting quick")
    p.add_argument("--out", required=True, metavar="DIR", help="study folder: datasets, runs, report (rerun to resume)")
    p.add_argument("--workers", type=value_type(positive_int, "an integer >= 1"), default=1,
                   help="training runs in parallel, one thread each (default: 1)")
    p.add_argument("--only", type=_experiments, default=(), metavar="EXP[,EXP]",
                   help="run only these experiments: t1, t3, speed, raw, fig4, labels (the label arm, with the GS "
                        "and exact-label runs of its speeds), coco (Table 2, no training) (default: all)")
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto",
                   help="auto: a CUDA GPU when the installed torch sees one (runs then go one at a time), else "
                        "the CPU (default: auto)")
    p.add_argument("--report", action="store_true",
                   help="train nothing: write the report of the runs already finished in --out (where a long "
                        "study stands)")
    p.add_argument("--adopt", action="append", default=[], metavar="DIR",
                   help="take over the finished runs of another copy of this study (its folder, or its report.json "
                        "with base.pt beside it, copied from another machine) instead of training them again; "
                        "checked to be of the same setting, datasets and base model (repeatable)")
    p.add_argument("--executor", default=None, metavar="SPEC", help="'local' or 'dask://HOST:PORT' for the runs")
    p.add_argument("--json", action="store_true", help="print the report's JSON document on stdout")
    p.add_argument("--progress", action="store_true", help="show progress even when stderr is not a terminal")
    return p


def _experiments(text: str) -> tuple[str, ...]:
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    bad = [n for n in names if n not in EXPERIMENTS]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"{text!r}: each experiment must be one of {list(EXPERIMENTS)}")
    return names


def run(args: argparse.Namespace) -> int:
    """Run the study and print its answers and where the report is."""
    from ..training.study import run_study
    from ..training.study_settings import SETTINGS
    from .compile_notice import notify_if_cold

    notify_if_cold()
    settings = SETTINGS[args.setting]
    argv = getattr(args, "argv", None)
    command = shlex.join(["rollcam", *argv]) if argv else None
    doc = run_study(settings, args.out, workers=args.workers, executor=args.executor,
                    progress=True if args.progress else None, command=command, only=args.only,
                    device=args.device, report_only=args.report, adopt_from=tuple(args.adopt))
    if doc["timing"]["device"] == "cuda":
        print("study: training on the CUDA GPU torch sees (runs one at a time)")
    if args.json:
        print(json.dumps(doc))
        return 0
    for line in doc["answers"]:
        print(line)
    if args.report or doc["timing"]["finished"] < doc["timing"]["planned"]:
        print(f"study {settings.name}: {doc['timing']['finished']} of {doc['timing']['planned']} runs finished; "
              f"report {args.out}/report.md")
        return 0
    print(f"study {settings.name}: {len(doc['runs'])} runs in {doc['timing']['total_s'] / 60:.1f} min; report "
          f"{args.out}/report.md")
    return 0
