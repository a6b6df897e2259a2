"""The system programs some tests drive (v4l2-ctl, ffmpeg, ...): found on PATH, or the test is skipped naming
the package that brings them (``.ci/run`` installs them all, so CI runs every one)."""

from __future__ import annotations

import shutil

import pytest

PACKAGES = {"v4l2-ctl": "v4l-utils", "v4l2-compliance": "v4l-utils", "gst-launch-1.0": "gstreamer1.0-tools"}
"""Debian package of each program whose package is not named after it."""


def need(program: str) -> str:
    """The path of ``program``, or skip the calling test saying what to install."""
    path = shutil.which(program)
    if path is None:
        pytest.skip(f"{program} is not installed (apt-get install {PACKAGES.get(program, program)})")
    return path
