"""Stand-in modules for unmodified programs: where they live, and the environment that makes a child find them.

``shims_path()`` is the folder holding rollcam's stand-in ``picamera2`` (and the small ``libcamera`` it
imports); put it first on ``sys.path`` / ``PYTHONPATH`` and ``import picamera2`` finds the emulated camera.
``standin_env(sources)`` is the environment for a child process: that folder prepended to ``PYTHONPATH`` and
``ROLLCAM_PICAMERA2`` naming the cameras (sensor names or ``emu:`` URIs; camera N is the N-th).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

from rollcam.common.errors import ConfigError

PICAMERA2_ENV = "ROLLCAM_PICAMERA2"
"""Environment variable naming the stand-in picamera2's cameras, separated by ';' (default: imx219)."""


def shims_path() -> Path:
    """The folder of rollcam's stand-in modules (``picamera2``, ``libcamera``), installed with rollcam."""
    return Path(__file__).resolve().parents[1] / "shims"  # host/shims, beside this package


def standin_env(sources: Sequence[str] = (), env: Mapping[str, str] | None = None) -> dict[str, str]:
    """``env`` (default: this process's) with the stand-ins first on ``PYTHONPATH`` and, when ``sources`` are
    given, ``ROLLCAM_PICAMERA2`` set to them."""
    out = dict(os.environ if env is None else env)
    paths = [str(shims_path()), *[p for p in out.get("PYTHONPATH", "").split(os.pathsep) if p]]
    out["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(paths))
    if sources:
        bad = [s for s in sources if not isinstance(s, str) or ";" in s or not s.strip()]
        if bad:
            raise ConfigError(f"camera sources {bad!r} must be non-empty text without ';'")
        out[PICAMERA2_ENV] = ";".join(s.strip() for s in sources)
    return out
