"""numba's on-disk cache never runs a kernel compiled against an older version of a module it calls into."""

from __future__ import annotations

import importlib
import os
import pkgutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
import rollcam.sim
from rollcam.sim import _jitcache

DEP = """
from numba import njit
from rollcam.sim._jitcache import guard

@njit(cache=True)
def f():
    return {value}

guard(__name__)
"""
MID = """
from numba import njit
from rollcam.sim._jitcache import guard
from .dep import f

@njit(cache=True)
def g():
    return f() + 10

guard(__name__)
"""
TOP = """
from numba import njit
from rollcam.sim._jitcache import guard
from . import mid as M

@njit(cache=True)
def h():
    return M.g() + 100

guard(__name__)
"""
RUN = ("from kpkg.top import h; from kpkg.mid import g; "
       "print(h(), g(), sum(h.stats.cache_hits.values()), sum(g.stats.cache_hits.values()))")


def _package(root: Path, value: int) -> None:
    pkg = root / "kpkg"
    pkg.mkdir(exist_ok=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "mid.py").write_text(MID)
    (pkg / "top.py").write_text(TOP)
    _edit_dep(root, value)


def _edit_dep(root: Path, value: int, caches: tuple[Path, ...] = ()) -> None:
    # The cache files written so far are made a minute old, so the edit is clearly newer whatever the grain
    # of the file system's clock.
    past = time.time() - 60
    for folder in caches:
        for f in folder.rglob("*.nb[ci]"):
            os.utime(f, (past, past))
    (root / "kpkg" / "dep.py").write_text(DEP.format(value=value))


def _run(root: Path, cache_dir: Path | None) -> tuple[int, int, int, int]:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["PYTHONPATH"] = os.pathsep.join([str(root), env.get("PYTHONPATH", "")])
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = str(cache_dir)
    res = subprocess.run([sys.executable, "-c", RUN], cwd=root, env=env, capture_output=True, text=True,
                         timeout=300, check=False)
    assert res.returncode == 0, res.stderr[-3000:]
    h, g, h_hits, g_hits = (int(v) for v in res.stdout.split())
    return h, g, h_hits, g_hits


@pytest.mark.parametrize("where", ["in-tree", "NUMBA_CACHE_DIR"])
def test_a_kernel_whose_dependency_changed_is_recompiled(tmp_path: Path, where: str):
    """top.h calls mid.g (by module attribute), which calls dep.f (imported by name): both callers compile f
    into themselves, and after an edit of dep.py neither may run the old f from cache, however deep."""
    root = tmp_path / "src"
    root.mkdir()
    cache_dir = tmp_path / "numba-cache" if where == "NUMBA_CACHE_DIR" else None
    _package(root, 1)
    assert _run(root, cache_dir)[:2] == (111, 11)
    assert _run(root, cache_dir) == (111, 11, 1, 1)  # cached: the check below is about a real cache
    _edit_dep(root, 2, (root,) if cache_dir is None else (cache_dir,))
    assert _run(root, cache_dir)[:2] == (112, 12)
    assert _run(root, cache_dir) == (112, 12, 1, 1)  # and the fresh compile is cached in turn


def test_every_module_with_cached_kernels_is_guarded():
    for info in pkgutil.iter_modules(rollcam.sim.__path__):
        if (Path(info.module_finder.path) / f"{info.name}.py").is_file():  # not the C shader's plain .so
            importlib.import_module(f"rollcam.sim.{info.name}")
    importlib.import_module("rollcam.host.detectors.ops")  # the one cached kernel outside the simulator: NMS
    with_kernels = {name for name, mod in list(sys.modules.items())
                    if name.startswith("rollcam.") and mod is not None and _jitcache.kernels(mod)}
    assert {"rollcam.sim.render.lines", "rollcam.host.detectors.ops"} <= with_kernels
    assert with_kernels <= _jitcache.guarded(), with_kernels - _jitcache.guarded()
    # The line kernel compiles in the actors, which compile in the walker, the props, the part writer and the
    # world (whose materials are the C shader's, called by name, not compiled in).
    actors = {"body.py", "parts.py", "props.py", "world.py"}
    assert {p.name for p in _jitcache.compiled_in("rollcam.sim.render.lines")} == actors | {"actors.py", "texture.py"}
    assert {p.name for p in _jitcache.compiled_in("rollcam.sim.render.actors")} == actors
    assert _jitcache.compiled_in("rollcam.sim.render.world") == frozenset()
    assert _jitcache.compiled_in("rollcam.sim.render.body") == frozenset()
