"""The system programs some tests drive (v4l2-ctl, ffmpeg, ...): found on PATH, or the test is skipped naming
the package that brings them (``.ci/run`` installs them all, so CI runs every one)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from rollcam.emu.v4l2.server import PreloadServer
from rollcam.host.servers.devnodes import program_environment

PACKAGES = {"v4l2-ctl": "v4l-utils", "v4l2-compliance": "v4l-utils", "gst-launch-1.0": "gstreamer1.0-tools"}
"""Debian package of each program whose package is not named after it."""


def need(program: str) -> str:
    """The path of ``program``, or skip the calling test saying what to install."""
    path = shutil.which(program)
    if path is None:
        pytest.skip(f"{program} is not installed (apt-get install {PACKAGES.get(program, program)})")
    return path


def run_under(server: PreloadServer, *argv: str, timeout: float = 120, check: bool = True,
              env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """Run a program under the preload library with ``server``'s devices (``env``: instead of the usual one);
    with ``check``, a non-zero exit fails the test showing its output."""
    p = subprocess.run(list(argv), env=env or program_environment(server), capture_output=True, text=True,
                       timeout=timeout)
    if check:
        assert p.returncode == 0, (p.returncode, p.stdout[-2000:], p.stderr[-2000:])
    return p


def python_under(server: PreloadServer, code: str, timeout: float = 120, env: dict[str, str] | None = None
                 ) -> dict:
    """Run ``code`` in a child Python under the preload library; its last stdout line is JSON."""
    p = run_under(server, sys.executable, "-c", textwrap.dedent(code), timeout=timeout, env=env)
    return json.loads(p.stdout.strip().splitlines()[-1])


def compile_c(out: Path, *args: str) -> Path:
    """``gcc -o out ARGS`` (sources and flags), or skip the calling test when there is no gcc."""
    subprocess.run([need("gcc"), "-o", str(out), *args], check=True, capture_output=True, text=True)
    return out
