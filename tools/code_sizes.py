"""List the classes over ~200 lines and the modules over ~500 (the code-size guides of STYLE.md).

Run from the repository root: `python tools/code_sizes.py [FOLDER ...]`. Prints one line per offender and exits 0;
it is a report, not a gate (declarative tables such as sim/hwconfig.py may stay long on purpose).
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

FOLDERS = ("common", "sim", "firmware", "emu", "host", "benchmarks")
CLASS_LINES = 200
MODULE_LINES = 500


def offenders(root: Path, folders: tuple[str, ...] = FOLDERS) -> list[str]:
    """One line per module over MODULE_LINES and per class over CLASS_LINES under `folders` of `root`."""
    found = []
    for folder in folders:
        for path in sorted((root / folder).rglob("*.py")):
            text = path.read_text()
            lines = len(text.splitlines())
            rel = path.relative_to(root)
            if lines > MODULE_LINES:
                found.append(f"module {rel}: {lines} lines")
            for node in ast.walk(ast.parse(text)):
                if isinstance(node, ast.ClassDef):
                    size = node.end_lineno - node.lineno + 1
                    if size > CLASS_LINES:
                        found.append(f"class  {rel}:{node.lineno} {node.name}: {size} lines")
    return found


if __name__ == "__main__":
    for line in offenders(Path.cwd(), tuple(sys.argv[1:]) or FOLDERS):
        print(line)
