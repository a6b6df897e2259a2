"""Say once, on stderr, that the renderer is about to compile, when numba's cache of it is cold.

The first render on a machine (or after an edit of the kernels) compiles them (about 100 s of CPU time, measured in
the README's Set up); a command that is silent that long looks hung. A warm cache says nothing, so the notice
appears exactly when it is true.
"""

from __future__ import annotations

import sys
from typing import TextIO

from rollcam.sim.kernel_cache import renderer_cache_cold

NOTICE = ("rollcam: compiling the renderer (first use on this machine, about 100 s of CPU time; later runs load it "
          "from numba's cache)")


def renders(uri: str) -> bool:
    """Whether opening source ``uri`` runs rollcam's renderer (``emu:`` and the emulated UVC backend)."""
    return uri.lower().startswith("emu:") or (uri.lower().startswith("uvc:") and "backend=emu" in uri.lower())


def notify_if_cold(stream: TextIO | None = None) -> bool:
    """Print ``NOTICE`` when the renderer's cache is cold; returns whether it did."""
    if not renderer_cache_cold():
        return False
    print(NOTICE, file=stream or sys.stderr, flush=True)
    return True
