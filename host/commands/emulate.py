"""``rollcam emulate SENSOR``: serve an emulated camera until Ctrl-C (options and work in ``rollcam.host.emulate``).

A thin registration: the emulate options are defined in ``rollcam.host.emulate.register`` beside the
transports they configure, and this module only hooks them into the command table.
"""

from __future__ import annotations

import argparse

from rollcam.common.errors import ConfigError
from rollcam.common.values import non_negative_float


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add ``rollcam emulate`` (its options come from ``rollcam.host.emulate``)."""
    from ..emulate import register

    register(sub)
    return sub.choices["emulate"]


def run(args: argparse.Namespace) -> int:
    """Serve until Ctrl-C, SIGTERM or ``--duration``."""
    from ..emulate import cmd_emulate

    if args.duration is not None:
        # --duration's argparse type belongs with the other emulate options; until it moves there it is
        # checked here with the common value parser, before any server starts.
        try:
            non_negative_float(str(args.duration))
        except ValueError as exc:
            raise ConfigError(f"emulate: argument --duration: {args.duration:g} is invalid: {exc}") from None
    return int(cmd_emulate(args) or 0)
