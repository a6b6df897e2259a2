"""``rollcam study``: the study's experiments end to end (datasets, training, tests, report)."""

from __future__ import annotations

import argparse
import json
import shlex

from rollcam.common.values import positive_int

from . import Subparsers, value_type

DESCRIPTION = """\
Reproduce the study's experiments with rollcam's own detector: build (or reuse) paired GS/RS datasets, train
one model per subset and seed, test each on the GS, RS and pooled test splits, and write OUT/report.md,
OUT/report.json and OUT/report.png: the Table 1 and Table 3 analogues beside the study's numbers, the RS
penalty against walking speed (RGB and raw-mosaic input), accuracy against the number of training scenes and
camera views (Fig. 4), with mean, spread and a significance flag over the seeds. Settings: quick (CI-sized,
minutes), reduced (the CPU setting: within 2 hours on 2 cores with --workers 2), full (the study's design at
1080p, for a GPU). Interrupt and rerun the same command: it resumes. Needs the 'train' extra."""

EPILOG = """\
examples:
  rollcam study --quick --out rollcam_out/study_quick
  rollcam study --setting reduced --workers 2 --out rollcam_out/study_reduced
  rollcam study --setting full --out /data/study_full                      # on a GPU machine"""


def add_parser(sub: Subparsers) -> argparse.ArgumentParser:
    """Add ``rollcam study``."""
    p = sub.add_parser("study", help="the study's tables end to end: datasets, training, tests, report",
                       description=DESCRIPTION, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--setting", choices=("quick", "reduced", "full"), default="reduced",
                   help="experiment size (default: %(default)s)")
    p.add_argument("--quick", action="store_const", const="quick", dest="setting", help="same as --setting quick")
    p.add_argument("--out", required=True, metavar="DIR", help="study folder: datasets, runs, report (rerun to resume)")
    p.add_argument("--workers", type=value_type(positive_int, "an integer >= 1"), default=1,
                   help="training runs in parallel, one thread each (default: 1)")
    p.add_argument("--executor", default=None, metavar="SPEC", help="'local' or 'dask://HOST:PORT' for the runs")
    p.add_argument("--json", action="store_true", help="print the report's JSON document on stdout")
    p.add_argument("--progress", action="store_true", help="show progress even when stderr is not a terminal")
    return p


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
                    progress=True if args.progress else None, command=command)
    if args.json:
        print(json.dumps(doc))
        return 0
    for line in doc["answers"]:
        print(line)
    print(f"study {settings.name}: {len(doc['runs'])} runs in {doc['timing']['total_s'] / 60:.1f} min; report "
          f"{args.out}/report.md")
    return 0
