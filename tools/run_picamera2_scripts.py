"""Run a folder of picamera2 scripts unchanged on rollcam's stand-in and report which pass (docs/picamera2.md).

Usage, from the repository root: `python tools/run_picamera2_scripts.py FOLDER [FOLDER ...] [--timeout S]
[--only NAME ...] [--json OUT]`. It fetches nothing: point it at a checkout of picamera2's `examples/` and
`tests/` (or any scripts written for picamera2). Each script runs in a fresh scratch folder with only
`rollcam.host.standin_env` (the stand-in first on PYTHONPATH, the cameras named in ROLLCAM_PICAMERA2), stdin
closed and no display. A script is

- `n/a` when it needs what the stand-in cannot give: a display (a Qt application, an OpenCV window), a
  Pi-only module or accelerator (Hailo, the IMX708 device helper), a network peer (it waits for a client to
  connect, or sends to an address to fill in), or a module this Python lacks;
- `pass` when it exits 0 without printing a line that starts with ``ERROR`` (picamera2's tests report failures
  so and go on), or when it is still running at the timeout without having printed a traceback and it
  is written to run until stopped (a server, a `while True` loop);
- `fail` otherwise, with the last line of its error output.
"""

from __future__ import annotations

import argparse
import ast
import importlib.util
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from rollcam.host.servers.standins import standin_env

DISPLAY = re.compile(r"PyQt[56]|PySide[26]|QApplication|picamera2\.previews\.qt|cv2\.imshow|cv2\.namedWindow")
"""What needs a person to look at a window. Preview windows (``Preview.QTGL``, ``show_preview=True``) are not
here: the stand-in runs them as the NULL preview, so the script still runs."""

PI_ONLY = {"picamera2.devices.hailo": "Hailo accelerator", "picamera2.devices.imx708": "the IMX708 device helper",
           "pose_utils": "Hailo pose helpers", "ai_edge_litert": "TF Lite models stored outside git (LFS)"}
"""Imports that need a Pi, an accelerator, or files the published repository does not carry."""

def runs_until_stopped(text: str) -> bool:
    """True for a script written to run until stopped: a server (``serve_forever``), or a ``while True`` loop
    of the script itself (not one inside a function, which may return)."""
    if "serve_forever(" in text:
        return True
    try:
        tree = ast.parse(text)
    except SyntaxError:
        return False

    def walk(nodes: list[ast.stmt]) -> bool:
        for node in nodes:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                continue
            if isinstance(node, ast.While) and isinstance(node.test, ast.Constant) and node.test.value is True:
                return True
            children = [getattr(node, f, []) for f in ("body", "orelse", "finalbody", "handlers")]
            if any(walk([c for c in group if isinstance(c, ast.stmt)]) for group in children if group):
                return True
            if isinstance(node, ast.Try) and any(walk(h.body) for h in node.handlers):
                return True
        return False

    return walk(tree.body)

NETWORK_PEER = re.compile(r"\.accept\(\)|[\"']REMOTEIP[\"']")
"""Scripts that wait for a client to connect, or send to an address the user must fill in."""

SOURCES = {"imx500": ("imx500",), "imx708": ("imx708", "imx219"), "autofocus": ("imx708", "imx219"),
           "multiplexer": ("imx219",) * 4}
"""Cameras for scripts whose name asks for a sensor (first match); others get two cameras (imx219, imx477)."""
DEFAULT_SOURCES = ("imx219", "imx477")


@dataclass
class Result:
    """One script's outcome."""

    script: str
    status: str  # pass, fail, n/a
    reason: str
    seconds: float


def imports_of(text: str) -> set[str]:
    """Every module a script imports (dotted names and their parents)."""
    names: set[str] = set()
    try:
        tree = ast.parse(text)
    except SyntaxError:
        return names
    for node in ast.walk(tree):
        found = []
        if isinstance(node, ast.Import):
            found = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            found = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        for name in found:
            parts = name.split(".")
            names.update(".".join(parts[:i]) for i in range(1, len(parts) + 1))
    return names


def not_applicable(path: Path, siblings: set[str]) -> str | None:
    """Why the script cannot run on the stand-in, or None."""
    text = path.read_text(errors="replace")
    shown = DISPLAY.search(text)
    if shown:
        return f"needs a display ({shown.group(0)})"
    peer = NETWORK_PEER.search(text)
    if peer and not (peer.group(0) == ".accept()" and "127.0.0.1" in text):  # its own client is no peer
        return f"needs a network peer ({peer.group(0)})"
    mods = imports_of(text)
    for mod, why in PI_ONLY.items():
        if mod in mods:
            return f"needs {why} ({mod})"
    for mod in sorted(m for m in mods if "." not in m):
        if mod in siblings:
            shown = DISPLAY.search((path.parent / f"{mod}.py").read_text(errors="replace"))
            if shown:
                return f"needs a display (through {mod}: {shown.group(0)})"
            continue
        if mod in ("picamera2", "libcamera"):
            continue
        if importlib.util.find_spec(mod) is None:
            return f"needs module {mod!r}, not installed here"
    return None


def sources_for(path: Path) -> tuple[str, ...]:
    """The cameras a script runs with."""
    for key, sources in SOURCES.items():
        if key in str(path):
            return sources
    return DEFAULT_SOURCES


def run_one(path: Path, timeout_s: float, forever_s: float, netns: bool = False) -> Result:
    """Run one script in a scratch folder (one written to run until stopped for ``forever_s``; ``netns``: in a
    network namespace of its own, which needs root); its Result."""
    siblings = {p.stem for p in path.parent.glob("*.py")}
    name = str(path)
    why = not_applicable(path, siblings)
    if why:
        return Result(name, "n/a", why, 0.0)
    env = standin_env(sources_for(path))
    env["PYTHONPATH"] = f"{env['PYTHONPATH']}:{path.parent}"
    env.pop("DISPLAY", None)
    env.pop("WAYLAND_DISPLAY", None)
    forever = runs_until_stopped(path.read_text(errors="replace"))
    if forever:
        timeout_s = min(timeout_s, forever_s)
    start = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="picamera2-script-") as scratch:
        for item in path.parent.iterdir():  # the script's own files (assets/, labels) where it looks for them
            if not item.name.endswith(".py"):
                (Path(scratch) / item.name).symlink_to(item.resolve())
        command = [sys.executable, str(path.resolve())]
        if netns:  # a network namespace of its own: its ports clash with nothing else on the machine
            command = ["unshare", "--net", "sh", "-c", 'ip link set lo up && exec "$@"', "sh", *command]
        proc = subprocess.Popen(command, cwd=scratch, env=env,
                                stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, errors="replace", start_new_session=True)
        try:
            out, err = proc.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            out, err = proc.communicate()
            errors = reported_errors(out)
            if errors:
                return Result(name, "fail", f"reported {errors[0]!r}", time.monotonic() - start)
            seconds = time.monotonic() - start
            if forever and "Traceback" not in err:
                return Result(name, "pass", f"still running after {timeout_s:.0f} s (runs until stopped)", seconds)
            return Result(name, "fail", f"timed out after {timeout_s:.0f} s: {last_line(err)}", seconds)
    seconds = time.monotonic() - start
    errors = reported_errors(out)
    if proc.returncode == 0 and errors:
        return Result(name, "fail", f"exit 0 but reported {errors[0]!r}", seconds)
    if proc.returncode == 0:
        return Result(name, "pass", "", seconds)
    return Result(name, "fail", f"exit {proc.returncode}: {last_line(err)}", seconds)


def reported_errors(out: str) -> list[str]:
    """The lines where a script says it failed (picamera2's tests print ``ERROR: ...`` and go on)."""
    return [ln.strip()[:200] for ln in out.splitlines() if ln.lstrip().startswith("ERROR")]


def last_line(err: str) -> str:
    """The line of error output that says what went wrong."""
    lines = [ln.strip() for ln in err.strip().splitlines() if ln.strip()]
    return lines[-1][:300] if lines else "(no error output)"


def main(argv: list[str] | None = None) -> int:
    """Run the scripts and print one line each, then the counts."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="+", type=Path)
    parser.add_argument("--timeout", type=float, default=120.0, help="seconds per script (default 120)")
    parser.add_argument("--forever", type=float, default=30.0,
                        help="seconds a script written to run until stopped must survive (default 30)")
    parser.add_argument("--netns", action="store_true",
                        help="run each script in a network namespace of its own (root; `unshare`, `ip`)")
    parser.add_argument("--only", nargs="*", default=None, help="script names (stems) to run")
    parser.add_argument("--json", type=Path, default=None, help="write the results here")
    args = parser.parse_args(argv)
    scripts = []
    for folder in args.folders:
        if not folder.is_dir():
            parser.error(f"{folder} is not a folder")
        scripts += sorted(folder.glob("*.py"))
    if args.only:
        scripts = [s for s in scripts if s.stem in args.only]
    results = []
    for path in scripts:
        res = run_one(path, args.timeout, args.forever, args.netns)
        results.append(res)
        print(f"{res.status:5} {res.seconds:6.1f}s {res.script} {res.reason}", flush=True)
    applicable = [r for r in results if r.status != "n/a"]
    passed = [r for r in applicable if r.status == "pass"]
    print(f"applicable {len(applicable)}, passed {len(passed)}, failed {len(applicable) - len(passed)}, "
          f"not applicable {len(results) - len(applicable)}")
    if args.json:
        args.json.write_text(json.dumps([asdict(r) for r in results], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
