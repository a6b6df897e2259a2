"""The ``rollcam`` command line: demo, list, capture, detect, emulate, dataset, eval, bench.

Exit codes: 0 success, 2 bad usage or input (argparse errors, ``ConfigError`` and ``SourceError``), 1 any
other failure (``DeviceError``, ``ProtocolError`` and other ``RollcamError``s, OS errors, bugs), 130 after
Ctrl-C. ``RollcamError``s and OS errors are reported as one ``rollcam: error: ...`` line without a traceback.
Subcommands import their work lazily, so ``rollcam --help`` starts fast and works whatever optional part is
missing.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
import traceback
from collections.abc import Callable, Sequence
from typing import Any

from rollcam.common.errors import ConfigError, RollcamError, SourceError

PROG = "rollcam"
EXIT_OK, EXIT_FAILURE, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def _size(text: str) -> tuple[int, int]:
    from .sources.base import parse_size

    try:
        return parse_size(text)
    except RollcamError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _err(message: str) -> None:
    print(f"{PROG}: error: {message}", file=sys.stderr)


# ---------------------------------------------------------------------------------------------- commands
def cmd_capture(args: argparse.Namespace) -> int:
    """``rollcam capture``: frames of SOURCE to image files and frames.jsonl."""
    from .capture import CaptureInterrupted, capture
    from .sources import open_camera

    with open_camera(args.source) as source:
        try:
            result = capture(source, args.out, args.frames, shutter=args.shutter, fmt=args.format,
                             overwrite=args.overwrite, progress=True if args.progress else None,
                             command=[PROG, *args.argv])
        except CaptureInterrupted as exc:
            r = exc.result
            print(f"{PROG}: interrupted: kept {r.frames} complete frame(s) in {r.out_dir / 'frames.jsonl'}",
                  file=sys.stderr)
            if args.json:
                print(json.dumps(r.to_json()))
            return EXIT_INTERRUPTED
    if args.json:
        print(json.dumps(result.to_json()))
    else:
        short = "" if result.complete else f" (source ended after {result.frames} of {args.frames})"
        print(f"wrote {result.frames} frame(s), {result.images} image(s) to {result.out_dir}/ in "
              f"{result.seconds:.1f} s{short}; metadata in {result.out_dir / 'frames.jsonl'}")
    return EXIT_OK


def cmd_demo(args: argparse.Namespace) -> int:
    """``rollcam demo``: a short emulated rolling-shutter street video and a GS/RS contact sheet."""
    from .demo import default_size, run_demo

    size = args.size or default_size(args.sensor)  # checks the sensor name before the banner
    print(f"rendering {args.seconds:g} s of an emulated rolling-shutter street "
          "(the first run on a machine also compiles the renderer, ~30 s)...", file=sys.stderr)
    result = run_demo(args.out, seconds=args.seconds, sensor=args.sensor, size=size,
                      progress=True if args.progress else None)
    print(f"video:         {result.video}")
    print(f"contact sheet: {result.contact_sheet}")
    print(f"source:        {result.uri}")
    print(result.summary())
    return EXIT_OK


def sensor_rows() -> list[dict[str, Any]]:
    """One row per emulated sensor: name, shutter, default mode, fps, line time, readout, description."""
    from rollcam.sim.hwconfig import list_sensors, load_sensor

    rows = []
    for name in list_sensors():
        s = load_sensor(name)
        mode, timing = s.mode(), s.timing()
        rows.append({"name": s.name, "uri": f"emu:{s.name}", "shutter": s.shutter, "default_mode": mode.name,
                     "width": mode.width, "height": mode.height, "fps": round(timing.fps, 3),
                     "line_time_ns": timing.line_time_ns, "readout": s.readout.value,
                     "modes": [m.name for m in s.modes], "description": s.description})
    return rows


COMMAND_MODULES: tuple[str, ...] = ("emulate", "detect", "datasets.command", "evaluation.command")
"""Modules under ``rollcam.host`` that each add one command: ``register(sub)`` adds a subparser whose
``func(args) -> int`` runs it (import heavy work inside ``func``, so ``rollcam --help`` stays fast)."""

def cmd_list(args: argparse.Namespace) -> int:
    """``rollcam list``: the emulated sensors, then each device backend's cameras (or why there are none)."""
    from .discover import SECTIONS, discover

    rows = sensor_rows()
    devices = discover()
    if args.json:
        print(json.dumps({"emulated": rows, **devices}))
        return EXIT_OK
    print("Emulated sensors (open as emu:NAME):")
    header = ("NAME", "SHUTTER", "DEFAULT MODE", "FPS", "LINE TIME", "READOUT")
    table = [header] + [(r["name"], r["shutter"], r["default_mode"], f"{r['fps']:.2f}",
                         f"{r['line_time_ns']} ns", r["readout"]) for r in rows]
    widths = [max(len(row[i]) for row in table) for i in range(len(header))]
    for row in table:
        print("  " + "  ".join(c.ljust(w) if i in (0, 1, 2, 5) else c.rjust(w)
                               for i, (c, w) in enumerate(zip(row, widths, strict=True))).rstrip())
    for key, (heading, _) in SECTIONS.items():
        section = devices[key]
        print(f"\n{heading}:")
        for d in section["devices"]:
            extra = "  ".join(f"{k}={v}" for k, v in d.items() if k != "uri" and v not in ("", None))
            print(f"  {d['uri']}  {extra}".rstrip())
        if not section["devices"]:
            print(f"  none: {section['note']}")
    return EXIT_OK


def cmd_bench(args: argparse.Namespace, extra: Sequence[str]) -> int:
    """``rollcam bench``: hand the remaining arguments to ``rollcam.benchmarks.bench``."""
    try:
        bench = importlib.import_module("rollcam.benchmarks.bench")
    except ModuleNotFoundError as exc:
        if exc.name not in ("rollcam.benchmarks.bench", "rollcam.benchmarks"):
            raise
        _err("the benchmark suite (rollcam.benchmarks.bench) is not part of this installation")
        return EXIT_FAILURE
    parser = argparse.ArgumentParser(prog=f"{PROG} bench", description="Speed-versus-error benchmarks.")
    bench.add_arguments(parser)
    return int(bench.run(parser.parse_args(list(extra))) or 0)


# ---------------------------------------------------------------------------------------------- parser
def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with one subparser per command."""
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="rollcam: a rolling-shutter camera emulator with exact global/rolling ground truth.",
        epilog="Run 'rollcam COMMAND --help' for a command's options. Exit codes: 0 ok, 2 bad usage or input, "
               "1 other failure, 130 interrupted.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser("demo", help="render a short emulated rolling-shutter street: MP4 and contact sheet",
                       description="Stream a few seconds of an emulated rolling-shutter street scene with fast "
                                   "walkers; write an MP4 of the RS stream with GS and RS boxes and a PNG contact "
                                   "sheet of GS/RS pairs of the same instants.")
    p.add_argument("--out", default="rollcam_out/demo", help="output folder (default: %(default)s)")
    p.add_argument("--seconds", type=_positive_float, default=2.0,
                   help="stream time to render, in seconds (default: %(default)s)")
    p.add_argument("--sensor", default="letsroll", help="emulated sensor (see 'rollcam list'; default: %(default)s)")
    p.add_argument("--size", type=_size, default=None,
                   help="output WxH (default: the sensor's default mode halved to at most 960 wide)")
    p.add_argument("--progress", action="store_true", help="show progress even when stderr is not a terminal")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("list", help="list the emulated sensors and attached cameras",
                       description="List the emulated sensors (shutter, default mode, frame rate, line time), then "
                                   "V4L2, OAK and USB video devices; an empty section says why (backend missing, "
                                   "nothing plugged in).")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.set_defaults(func=cmd_list)

    p = sub.add_parser("capture", help="capture frames and their ground truth to image files and frames.jsonl",
                       description="Capture N frames of SOURCE into DIR: images NNNNNN_rs.png / NNNNNN_gs.png, "
                                   "DIR/frames.jsonl (one JSON record per image) and DIR/capture.json.",
                       epilog="SOURCE examples: 'emu:imx219?scene=street&speed=fast', 'emu:letsroll?size=960x540"
                              "&seed=3', 'file:clips/hfr?fps=960&line_time_ns=30864'. Quote URIs in the shell.")
    p.add_argument("source", metavar="SOURCE", help="source URI, e.g. 'emu:imx219?scene=street'")
    p.add_argument("--frames", type=_positive_int, required=True, metavar="N", help="instants to capture")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--shutter", choices=("rolling", "global", "both"), default=None,
                   help="'both' stores GS and RS frames of the same instants (default: the source's shutter)")
    p.add_argument("--format", choices=("png", "jpg", "npy"), default="png",
                   help="image file format (default: png; raw frames go losslessly into png or npy)")
    p.add_argument("--overwrite", action="store_true", help="replace an earlier capture in DIR")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("--progress", action="store_true", help="show progress even when stderr is not a terminal")
    p.set_defaults(func=cmd_capture)

    for name in COMMAND_MODULES:
        importlib.import_module(f"rollcam.host.{name}").register(sub)

    p = sub.add_parser("bench", add_help=False, help="speed-versus-error benchmarks ('rollcam bench --help')",
                       description="Run rollcam's benchmarks; options belong to rollcam.benchmarks.bench.")
    p.set_defaults(func=None, bench=True)
    return parser


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("rollcam")
    except PackageNotFoundError:
        return "unknown"


def _dispatch(argv: list[str]) -> int:
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if getattr(args, "bench", False):
        return cmd_bench(args, extra)
    if extra:
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    args.argv = argv
    func: Callable[[argparse.Namespace], int] = args.func
    return func(args)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``rollcam`` console script; returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        return _dispatch(argv)
    except KeyboardInterrupt:
        print(f"\n{PROG}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except (ConfigError, SourceError) as exc:  # a bad option, value, config or source URI
        _err(str(exc))
        return EXIT_USAGE
    except RollcamError as exc:  # the device, a protocol or the work itself failed
        _err(str(exc))
        return EXIT_FAILURE
    except BrokenPipeError:
        # Output piped into something that stopped reading (``rollcam list | head``): not a failure worth a trace.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_FAILURE
    except OSError as exc:
        _err(str(exc))
        return EXIT_FAILURE
    except Exception:
        traceback.print_exc()
        _err("unexpected failure (the traceback above is a bug report's best friend)")
        return EXIT_FAILURE


if __name__ == "__main__":
    sys.exit(main())
