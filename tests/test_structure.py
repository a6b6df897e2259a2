"""The package's structure holds (DESIGN.md, STYLE.md "Structure over size"): no import cycle, function-local
imports included; no module imports another's private names; no reach into another object's private attributes;
layers import downwards only (benchmarks -> host -> emu -> firmware -> sim -> common).

tools/structure.py reads the modules with `ast` and finds each case; `python tools/structure.py` prints them all.
What may stay is listed below with the reason, keyed without line numbers so an edit elsewhere keeps its entry.
An entry that no longer matches anything fails too, so the lists only shrink.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[1]

FOLLOW_UP = ("a reach between cooperating classes inside one subsystem, not across subsystems; to get a public "
             "accessor when that subsystem is next reworked")

ALLOWED_CYCLES: dict[frozenset[str], str] = {}
"""Sets of modules that import each other, each with why it may stay for now."""

ALLOWED_PRIVATE_IMPORTS: dict[tuple[str, str], str] = {}
"""(file, private name of another module it imports or reads) -> why it may stay for now."""

ALLOWED_PRIVATE_ATTRIBUTES: dict[tuple[str, str], str] = {
    ("sim/_jitcache.py", "kernel._cache"):
        "numba gives no public name for a cached function's index file; cache_index is the one reader",
    ("host/commands/__init__.py", "argparse._SubParsersAction"):
        "argparse gives its subparsers class no public name; Subparsers is the one alias every command uses",
    ("host/commands/run.py", "argparse._SubParsersAction"): FOLLOW_UP + " (`rollcam run`): use Subparsers",
    ("emu/v4l2/driver.py", "d._stop_pump"): FOLLOW_UP + " (emu/v4l2)",
    ("emu/v4l2/driver.py", "d._filling"): FOLLOW_UP + " (emu/v4l2)",
    ("host/shims/picamera2/_cnn.py", "cam._cam"): FOLLOW_UP + " (the picamera2 stand-in)",
    ("host/shims/picamera2/request.py", "self._request._array"): FOLLOW_UP + " (the picamera2 stand-in)",
    ("host/shims/libcamera/__init__.py", "other._key"): "ColorSpace.__eq__ compares with another ColorSpace",
    # picamera2's own API names its outputs' hook _add_stream and its encoders call it so: a replica keeps it.
    ("host/shims/picamera2/encoders/encoder.py", "output._add_stream"): "picamera2's API (Output._add_stream)",
    ("host/shims/picamera2/outputs/circularoutput2.py", "output._add_stream"): "picamera2's API (Output._add_stream)",
    ("host/shims/picamera2/outputs/splittableoutput.py", "new_output._add_stream"):
        "picamera2's API (Output._add_stream)",
    ("host/shims/picamera2/outputs/splittableoutput.py", "self._output._add_stream"):
        "picamera2's API (Output._add_stream)",
    ("host/shims/picamera2/remote.py", "self._request._array_ref_count"):
        "the stand-in's RemoteRequest internals, read by its RemoteMappedArray; " + FOLLOW_UP,
    ("host/shims/picamera2/remote.py", "self._request._arrays"):
        "the stand-in's RemoteRequest internals, read by its RemoteMappedArray; " + FOLLOW_UP,
    ("host/shims/picamera2/remote.py", "request._kwargs"): "the stand-in's RemoteRequest internals; " + FOLLOW_UP,
    ("host/shims/picamera2/remote.py", "self._processes[i]._sent"):
        "the stand-in's Pool reads its Process queue lengths; " + FOLLOW_UP,
}
"""(file, `obj._attr` with obj not self/cls) -> why it may stay for now."""


def _tool() -> ModuleType:
    spec = importlib.util.spec_from_file_location("structure", ROOT / "tools" / "structure.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("structure", module)  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def tool() -> ModuleType:
    return _tool()


@pytest.fixture(scope="module")
def modules(tool: ModuleType) -> dict:
    return tool.load(ROOT)


def test_no_import_cycles(tool: ModuleType, modules: dict) -> None:
    found = {frozenset(c): c for c in tool.cycles(modules)}
    new = [" <-> ".join(c) for key, c in found.items() if key not in ALLOWED_CYCLES]
    gone = [sorted(key) for key in ALLOWED_CYCLES if key not in found]
    assert not new, "import cycles (give what the modules share a public home below both):\n" + "\n".join(new)
    assert not gone, f"allowed cycles that no longer exist: drop them from ALLOWED_CYCLES: {gone}"


def _against_allow_list(found: list, allowed: dict, what: str, fix: str) -> None:
    """Fail on a finding the allow-list does not name, and on an allow-list entry that matches nothing."""
    new = [str(f) for f in found if (f.path, f.key) not in allowed]
    gone = set(allowed) - {(f.path, f.key) for f in found}
    assert not new, f"{what} ({fix}):\n" + "\n".join(new)
    assert not gone, f"allowed {what} that no longer exist: drop them: {sorted(gone)}"


def test_no_module_imports_another_modules_private_names(tool: ModuleType, modules: dict) -> None:
    _against_allow_list(tool.private_imports(modules), ALLOWED_PRIVATE_IMPORTS,
                        "private names imported across modules", "make them public where they live")


def test_no_reach_into_another_objects_private_attributes(tool: ModuleType, modules: dict) -> None:
    _against_allow_list(tool.private_attributes(modules), ALLOWED_PRIVATE_ATTRIBUTES,
                        "private attributes read off another object", "give the owner a public method")


def test_layers_import_downwards_only(tool: ModuleType, modules: dict) -> None:
    found = [str(f) for f in tool.layer_violations(modules)]
    assert not found, "imports against DESIGN.md's layer order:\n" + "\n".join(found)


# The checks themselves, on small made-up packages: each must find what it is for.

def _package(tmp_path: Path, files: dict[str, str]) -> dict:
    for rel, text in files.items():
        path = tmp_path / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return _tool().load(tmp_path)


def test_a_cycle_through_a_function_local_import_is_found(tmp_path: Path) -> None:
    modules = _package(tmp_path, {
        "sim/__init__.py": "",
        "sim/a.py": "from .b import B\n",
        "sim/b.py": "B = 1\n\ndef late():\n    from rollcam.sim import a\n    return a\n",
        "sim/c.py": "from rollcam.sim.a import B\n",
    })
    assert _tool().cycles(modules) == [["rollcam.sim.a", "rollcam.sim.b"]]


def test_private_imports_and_reads_are_found(tmp_path: Path) -> None:
    modules = _package(tmp_path, {
        "sim/__init__.py": "",
        "sim/a.py": "_SECRET = 1\nPUBLIC = 2\n",
        "sim/_inner.py": "X = 1\n",
        "sim/b.py": "from .a import _SECRET, PUBLIC\nfrom . import _inner\n",
        "emu/__init__.py": "",
        "emu/c.py": "from rollcam.sim import a, _inner\nY = a._SECRET + a.PUBLIC\n",
    })
    found = {(f.path, f.kind, f.key) for f in _tool().private_imports(modules)}
    assert found == {("sim/b.py", "private import", "rollcam.sim.a._SECRET"),
                     ("emu/c.py", "private module", "rollcam.sim._inner"),
                     ("emu/c.py", "private read", "rollcam.sim.a._SECRET")}


def test_private_attributes_of_other_objects_are_found(tmp_path: Path) -> None:
    modules = _package(tmp_path, {
        "sim/__init__.py": "",
        "sim/a.py": ("class A:\n    def f(self, other):\n        return self._x + other._y + super()._z"
                     " + self._p._q._r\n"),
    })
    found = [(f.key) for f in _tool().private_attributes(modules)]
    assert found == ["other._y", "self._p._q"]


def test_an_upward_import_is_found(tmp_path: Path) -> None:
    modules = _package(tmp_path, {
        "sim/__init__.py": "",
        "sim/a.py": "def f():\n    from rollcam.emu import b\n",
        "emu/__init__.py": "",
        "emu/b.py": "from rollcam.sim import a\n",
    })
    found = [(f.path, f.kind) for f in _tool().layer_violations(modules)]
    assert found == [("sim/a.py", "sim imports emu")]
