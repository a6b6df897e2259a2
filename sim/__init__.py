"""Simulation: scenes, per-row rendering, sensor timing, ground truth."""

import os as _os

# Numba's OpenMP workers otherwise spin while idle, which starves other processes (dataset workers, a
# detector) on small machines; passive waiting costs nothing measurable on an idle one.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
