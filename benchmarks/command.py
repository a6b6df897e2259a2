"""``rollcam bench STUDY``: one speed-versus-error study per call (the studies are ``rollcam.benchmarks``).

The command's module lives with the studies, on top of ``rollcam.host``, so no module of ``host`` imports
``benchmarks``: the command table (``rollcam.host.commands.COMMANDS``) names it like every other command.

Every study takes ``--out DIR`` (its JSON, and plots, go there), ``--json`` (the JSON document on stdout
instead of the report), ``--check`` (exit status 1 when a target is missed, naming each) and ``--progress``.
"""

from __future__ import annotations

import argparse
import json
from typing import Any

from rollcam.common.errors import ConfigError
from rollcam.host.commands import Subparsers

OLD_FLAGS = {"--quick": "render --quick", "--hog": "realism", "--detect": "detect", "--ptc": "ptc",
             "--sensor": "sensor", "--uvc": "uvc", "--soak": "soak", "--dataset": "dataset"}
"""The flags that picked a study before ``rollcam bench STUDY`` -> the subcommand that replaces each."""


class _OldFlag(argparse.Action):
    """An old study flag: refused at once with the new spelling (``--ptc S`` -> ``rollcam bench ptc S``)."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        new = " ".join([f"rollcam bench {OLD_FLAGS[option_string or '']}", *([values] if values else [])])
        raise ConfigError(f"bench: {option_string} is now {new!r}")


def add_parser(sub: Subparsers) -> argparse.ArgumentParser:
    """Add ``rollcam bench`` with one subcommand per study of ``rollcam.benchmarks.studies``."""
    from .studies import STUDIES

    p = sub.add_parser("bench", help="speed-versus-error studies, one per call ('rollcam bench STUDY --help')",
                       description="Run one of rollcam's benchmark studies: " + ", ".join(STUDIES) + ".")
    for flag in OLD_FLAGS:  # hidden; they only say what replaced them
        p.add_argument(flag, action=_OldFlag, nargs="?" if flag == "--ptc" else 0, help=argparse.SUPPRESS)
    studies = p.add_subparsers(dest="study", metavar="STUDY", required=True)
    for study in STUDIES.values():
        sp = studies.add_parser(study.name, help=study.help, description=study.help[0].upper() + study.help[1:] + ".")
        study.add_arguments(sp)
        g = sp.add_argument_group("every study")
        g.add_argument("--out", default="rollcam_out/bench", metavar="DIR",
                       help="folder for the study's JSON and plots (default: %(default)s)")
        g.add_argument("--json", action="store_true", help="print the JSON document instead of the report")
        g.add_argument("--check", action="store_true",
                       help="exit with status 1, naming each target missed, when the study misses one")
        g.add_argument("--progress", action="store_true", help="show progress even when stderr is not a terminal")
    return p


def run(args: argparse.Namespace) -> int:
    """Run the chosen study, print its report (or JSON), and with ``--check`` judge its targets."""
    from rollcam.host.commands.compile_notice import notify_if_cold
    from rollcam.host.progress import Progress

    from .studies import STUDIES, TargetMissed, missed

    study = STUDIES[args.study]
    notify_if_cold()
    bar = Progress(label=f"bench {study.name}", enabled=True if args.progress else None)
    try:
        doc, report = study.run(args, bar)
    finally:
        bar.close()
    print(json.dumps(doc, indent=1) if args.json else report, flush=True)
    if args.check:
        failed = missed(study.targets(doc))
        if failed:
            raise TargetMissed(f"bench {study.name}: {len(failed)} target(s) missed: {'; '.join(failed)}")
    return 0
