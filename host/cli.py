"""The ``rollcam`` command line: one subcommand per command module of ``rollcam.host.commands.COMMANDS``.

Exit codes (``rollcam.common.errors.exit_code``): 0 success; 2 bad usage or input (argparse errors,
``ConfigError``, ``SourceError``); 1 any other failure (``DeviceError`` such as a camera that is not there,
``ProtocolError``, ``MissingDependencyError``, other ``RollcamError``s, OS errors, bugs); 130 after Ctrl-C. Every
error is one ``rollcam: error: ...`` line on stderr, without a traceback (a bug adds its traceback above it).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import traceback
from collections.abc import Sequence
from typing import NoReturn

from rollcam.common.errors import EXIT_FAILURE, ConfigError, RollcamError, exit_code, is_interrupt

from .commands import COMMANDS, PROG


class UsageError(ConfigError):
    """A command line argparse refused; ``rollcam: error:`` and exit status 2, like any other bad input."""


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line (with the command and where its help is), not a usage block."""

    def error(self, message: str) -> NoReturn:
        command = self.prog[len(PROG):].strip()
        where = f"{command}: " if command else ""
        raise UsageError(f"{where}{message} (see '{self.prog} --help')")


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("rollcam")
    except PackageNotFoundError:
        return "unknown"


def build_parser() -> tuple[Parser, dict[str, argparse.ArgumentParser]]:
    """The top-level parser with one subparser per command module, and the subparsers by command name."""
    parser = Parser(
        prog=PROG,
        description="rollcam: a rolling-shutter camera emulator with exact global/rolling ground truth.",
        epilog="Run 'rollcam COMMAND --help' for a command's options. Exit codes: 0 ok, 2 bad usage or input, "
               "1 device, I/O or other failure, 130 interrupted.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True, parser_class=Parser)
    commands = {}
    for name, module_name in COMMANDS.items():
        module = importlib.import_module(module_name)
        p = module.add_parser(sub)
        p.set_defaults(run=module.run)
        commands[name] = p
    return parser, commands


def _dispatch(argv: list[str]) -> int:
    parser, commands = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:  # said by the command's own parser, so the hint points at its help
        commands[args.command].error(f"unrecognized arguments: {' '.join(extra)}")
    args.argv = argv
    return int(args.run(args) or 0)


def _err(message: str) -> None:
    print(f"{PROG}: error: {message}", file=sys.stderr)


def _interrupted(exc: BaseException) -> int:
    print(f"\n{PROG}: interrupted", file=sys.stderr)
    return exit_code(exc)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``rollcam`` console script; returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        return _dispatch(argv)
    except KeyboardInterrupt as exc:
        return _interrupted(exc)
    except BrokenPipeError:
        # Output piped into something that stopped reading (``rollcam list | head``): not a failure worth a trace.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_FAILURE
    except (RollcamError, OSError) as exc:
        _err(str(exc))
        return exit_code(exc)
    except Exception as exc:
        if is_interrupt(exc):  # Ctrl-C inside compiled code (see ``is_interrupt``)
            return _interrupted(exc)
        traceback.print_exc()
        _err("unexpected failure (the traceback above is a bug report's best friend)")
        return exit_code(exc)


if __name__ == "__main__":
    sys.exit(main())
