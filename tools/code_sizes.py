"""Report the classes over ~200 lines and the modules over ~500, Python and C (the size guides of STYLE.md).

Run from the repository root: `python tools/code_sizes.py [FOLDER ...]`. Prints one line per Python module or
class past its guide, then every C file with its length and its longest functions, and exits 0. It is a report,
not a gate: a long file is a question to ask, never a line count to trim to (STYLE.md "Structure over size";
the gate is tests/test_structure.py).
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

FOLDERS = ("common", "sim", "firmware", "emu", "host", "benchmarks")
CLASS_LINES = 200
MODULE_LINES = 500
C_FUNCTION_LINES = 100


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


def c_functions(text: str) -> list[tuple[str, int]]:
    """(name, lines) of each top-level function body of C source `text`, by brace depth (a report's accuracy)."""
    found = []
    depth, start, head = 0, 0, ""
    for number, line in enumerate(text.splitlines(), 1):
        code = line.split("//", 1)[0]
        if depth == 0:
            head = (head + " " + code) if "{" not in code else head + " " + code.split("{", 1)[0]
            if ";" in code and "{" not in code:
                head = ""
        for char in code:
            if char == "{":
                if depth == 0:
                    start = number
                depth += 1
            elif char == "}":
                depth -= 1
                if depth == 0:
                    match = re.search(r"(\w+)\s*\([^()]*(?:\([^()]*\)[^()]*)*\)\s*$", head.strip())
                    if match:
                        found.append((match.group(1), number - start + 1))
                    head = ""
    return found


def c_report(root: Path, folders: tuple[str, ...] = FOLDERS) -> list[str]:
    """One line per C file under `folders`: its lines and its functions past C_FUNCTION_LINES, longest first."""
    lines = []
    for folder in folders:
        for path in sorted((root / folder).rglob("*.c")):
            text = path.read_text()
            long = sorted((f for f in c_functions(text) if f[1] > C_FUNCTION_LINES), key=lambda f: -f[1])
            shown = ", ".join(f"{name} {size}" for name, size in long) or "none"
            lines.append(f"c      {path.relative_to(root)}: {len(text.splitlines())} lines; "
                         f"functions over {C_FUNCTION_LINES} lines: {shown}")
    return lines


def largest(root: Path, folders: tuple[str, ...] = FOLDERS, count: int = 5) -> list[str]:
    """The `count` longest Python classes and modules, whatever their size (two lines)."""
    classes, modules = [], []
    for folder in folders:
        for path in sorted((root / folder).rglob("*.py")):
            text = path.read_text()
            rel = path.relative_to(root)
            modules.append((len(text.splitlines()), str(rel)))
            classes += [(n.end_lineno - n.lineno + 1, f"{rel}:{n.name}") for n in ast.walk(ast.parse(text))
                        if isinstance(n, ast.ClassDef)]
    return [f"largest {kind}: " + ", ".join(f"{name} {size}" for size, name in sorted(items, reverse=True)[:count])
            for kind, items in (("classes", classes), ("modules", modules))]


def report(root: Path, folders: tuple[str, ...] = FOLDERS) -> list[str]:
    """The whole report: Python offenders, the largest classes and modules, then every C file."""
    return offenders(root, folders) + largest(root, folders) + c_report(root, folders)


if __name__ == "__main__":
    for line in report(Path.cwd(), tuple(sys.argv[1:]) or FOLDERS):
        print(line)
