"""The ``rollcam`` commands, one module each, registered the same way.

A command module (``rollcam.host.commands.<name>``, or ``rollcam.benchmarks.command`` for ``bench``) provides

- ``add_parser(subparsers) -> argparse.ArgumentParser``: its subparser, options and help;
- ``run(args) -> int``: the work, returning the exit status (errors are raised, ``rollcam.host.cli`` turns
  them into one ``rollcam: error:`` line and the status of ``rollcam.common.errors.exit_code``).

Command modules import only the standard library at the top; the work (numpy, OpenCV, the renderer, optional
packages) is imported inside ``run``, so ``rollcam --help`` starts fast and works whatever optional package is
missing. A new command is one module and one entry in ``COMMANDS``.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

COMMANDS: dict[str, str] = {
    "demo": "rollcam.host.commands.demo",
    "list": "rollcam.host.commands.list",
    "capture": "rollcam.host.commands.capture",
    "calibrate": "rollcam.host.commands.calibrate",
    "detect": "rollcam.host.commands.detect",
    "emulate": "rollcam.host.commands.emulate",
    "view": "rollcam.host.commands.view",
    "run": "rollcam.host.commands.run",
    "gadget": "rollcam.host.commands.gadget",
    "pipewire": "rollcam.host.commands.pipewire",
    "dataset": "rollcam.host.commands.dataset",
    "eval": "rollcam.host.commands.eval",
    "train": "rollcam.host.commands.train",
    "study": "rollcam.host.commands.study",
    "bench": "rollcam.benchmarks.command",
}
"""Command name -> its module, in the order ``rollcam --help`` lists them. ``bench`` lives with the studies it
runs (``rollcam.benchmarks``, the layer above ``host``): the table names it, so no ``host`` module imports it."""


PROG = "rollcam"

Subparsers = argparse._SubParsersAction
"""The type of the ``subparsers`` object every command's ``add_parser`` receives. argparse keeps the class under a
private name and gives no public one; this is the one place that reaches for it."""


def value_type(parse: Callable[[str], Any], what: str | None = None) -> Callable[[str], Any]:
    """An argparse ``type`` from a value parser of ``rollcam.common.values`` (or any ``str -> value``).

    A refused value becomes argparse's usage error naming the option and the value, with the parser's own
    reason (``must be an integer >= 1``) or ``what`` it expected when the reason is Python's (``invalid
    literal for int()``).
    """

    def convert(text: str) -> Any:
        try:
            return parse(text)
        except (TypeError, ValueError) as exc:
            reason = str(exc)
            if what is not None and (not reason or "invalid literal" in reason or "could not convert" in reason):
                reason = f"expected {what}"
            message = reason if repr(text) in reason else f"{text!r} is invalid: {reason}"
            raise argparse.ArgumentTypeError(message) from None

    convert.__name__ = getattr(parse, "__name__", "value")
    return convert
