"""Numba's on-disk kernel cache, made to notice edits to the kernels a cached function compiles in from elsewhere.

Numba keys a ``cache=True`` function on its own source file only, but a kernel that calls a kernel of another
module compiles that one into itself: after an edit of ``render/body.py`` the renderer's line kernel would keep
running the old walker from cache. So every module that defines cached kernels ends with ``guard(__name__)``.
The guard finds the kernel modules it uses (numba functions and kernel modules among its globals), adds the
ones those use in turn, and deletes this module's cache files older than the newest of those sources; numba
then compiles them afresh. A module whose kernels use nothing from elsewhere costs a dictionary lookup.
"""

from __future__ import annotations

import glob
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

from numba.core.dispatcher import Dispatcher

_SOURCES: dict[str, frozenset[Path]] = {}
"""Guarded module name -> source files of the other kernel modules it compiles in, transitively."""


def guard(name: str) -> None:
    """Drop the stale numba cache of module ``name``; call it last in the module, as ``guard(__name__)``."""
    module = sys.modules[name]
    sources: set[Path] = set()
    for used in _kernel_modules_used(module):
        sources.add(Path(used.__file__).resolve())
        sources |= _SOURCES.get(used.__name__, frozenset())
    _SOURCES[name] = frozenset(sources)
    if not sources:
        return
    newest = max(p.stat().st_mtime for p in sources)
    for f in _cache_files(module):
        _drop_if_older(f, newest)


def compiled_in(name: str) -> frozenset[Path]:
    """Source files of the kernel modules guarded module ``name`` compiles in (transitively)."""
    return _SOURCES[name]


def guarded() -> frozenset[str]:
    """Names of the modules that called ``guard``."""
    return frozenset(_SOURCES)


def kernels(module: ModuleType) -> list[Dispatcher]:
    """The numba functions defined in ``module`` (not those it imports)."""
    return [v for v in vars(module).values() if isinstance(v, Dispatcher) and v.py_func.__module__ == module.__name__]


def _kernel_modules_used(module: ModuleType) -> Iterator[ModuleType]:
    """Other modules whose kernels ``module``'s globals reach: imported numba functions, kernel modules."""
    seen = {module.__name__}
    for value in list(vars(module).values()):
        if isinstance(value, Dispatcher):
            used = sys.modules.get(value.py_func.__module__)
        elif isinstance(value, ModuleType) and getattr(value, "__file__", None) and kernels(value):
            used = value
        else:
            continue
        if used is not None and used.__name__ not in seen and getattr(used, "__file__", None):
            seen.add(used.__name__)
            yield used


def _drop_if_older(path: Path, mtime: float) -> None:
    try:
        if path.stat().st_mtime < mtime:
            path.unlink()
    except OSError:
        pass  # not cached yet, or a read-only install (where nothing is edited, so nothing is stale)


def cache_index(kernel: Dispatcher) -> Path | None:
    """The index file numba keeps for cached ``kernel`` (it may not exist yet); None without a cache.

    The one reader of numba's internals (as of 0.6x) for it: a kernel without a cache has a NullCache and no
    ``_cache_file``, and a numba that moved the path reads as no cache rather than a crash.
    """
    try:
        return Path(kernel._cache._cache_file._index_path)
    except AttributeError:
        return None


def _cache_files(module: ModuleType) -> Iterator[Path]:
    """The index and data files of every cached kernel of ``module``, wherever numba keeps them."""
    for kernel in kernels(module):
        index = cache_index(kernel)
        if index is None:
            continue
        yield index
        stem = glob.escape(index.name.removesuffix(".nbi"))
        yield from index.parent.glob(f"{stem}.*.nbc")
