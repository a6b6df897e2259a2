"""The size report (tools/code_sizes.py) runs and covers Python and C; sizes are a report, not a gate.

STYLE.md "Structure over size": a class past ~200 lines or a module past ~500 is a question to ask, never a count
to trim to; what fails the build is a cycle or a reach into private names (tests/test_structure.py). The report is
printed (`pytest -s tests/test_code_sizes.py`, or `python tools/code_sizes.py`).
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]


def _tool() -> ModuleType:
    spec = importlib.util.spec_from_file_location("code_sizes", ROOT / "tools" / "code_sizes.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_size_report_covers_python_and_c() -> None:
    lines = _tool().report(ROOT)
    print("\n".join(["", "code sizes (a report, not a gate):", *lines]), file=sys.stderr)
    c_files = sorted(str(p.relative_to(ROOT)) for folder in ("sim", "emu") for p in (ROOT / folder).rglob("*.c"))
    assert c_files, "the report should find the C sources"
    for rel in c_files:
        assert any(line.startswith(f"c      {rel}:") for line in lines), (rel, lines)
    assert any(line.startswith("largest classes: ") for line in lines)


def test_c_function_lengths_are_measured() -> None:
    text = ("static int f(int a)\n{\n    if (a) {\n        return 1;\n    }\n    return 0;\n}\n\n"
            "int x;\nvoid g(void) { }\n")
    assert _tool().c_functions(text) == [("f", 6), ("g", 1)]
