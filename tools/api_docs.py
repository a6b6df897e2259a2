"""Write docs/api.md, the reference of rollcam's public Python API, from the docstrings and signatures in the source.

Run from the repository root: ``python tools/api_docs.py`` rewrites docs/api.md; ``--check`` exits 1 when the file
is stale (tests/test_docs.py runs the same comparison). The source is read with ``ast``, not imported, so the
reference is the same on any machine, with or without the optional extras, and writing it runs no rollcam code.

What is public is listed in ``SECTIONS``: the entry points a user calls (``open_camera``, ``VideoCapture``, the
``rollcam run`` and ``rollcam emulate`` functions, the stand-in helpers), what they return (``CameraSource``,
``Frame``), the error tree, and the pytest plugin's fixtures.
"""

from __future__ import annotations

import ast
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = Path("docs") / "api.md"


@dataclass(frozen=True)
class Entry:
    """One documented name: its import path as a user writes it, the file that defines it, and its name there."""

    public: str
    path: str
    name: str


SECTIONS: tuple[tuple[str, str, tuple[Entry, ...]], ...] = (
    ("Opening a camera", "Every source URI (docs/sources.md) opens the same way and yields `Frame`s.", (
        Entry("rollcam.host.open_camera", "host/sources/__init__.py", "open_camera"),
        Entry("rollcam.host.sources.base.CameraSource", "host/sources/base.py", "CameraSource"),
        Entry("rollcam.host.VideoCapture", "host/videocapture.py", "VideoCapture"),
    )),
    ("Frames and their truth", "What every source yields, emulated or real (DESIGN.md's Frame contract).", (
        Entry("rollcam.sim.frame.Frame", "sim/frame.py", "Frame"),
        Entry("rollcam.sim.frame.ObjectTruth", "sim/frame.py", "ObjectTruth"),
    )),
    ("Devices for other programs", "What `rollcam run` and `rollcam emulate` do, callable from Python.", (
        Entry("rollcam.host.run_program", "host/servers/devnodes.py", "run_program"),
        Entry("rollcam.host.serving", "host/servers/devnodes.py", "serving"),
        Entry("rollcam.host.program_environment", "host/servers/devnodes.py", "program_environment"),
        Entry("rollcam.host.serve", "host/servers/emulate.py", "serve"),
        Entry("rollcam.host.shims_path", "host/servers/standins.py", "shims_path"),
        Entry("rollcam.host.standin_env", "host/servers/standins.py", "standin_env"),
        Entry("rollcam.host.cli.main", "host/cli.py", "main"),
    )),
    ("Errors", "One tree: catch `RollcamError` for any of them (all importable from `rollcam.host`).", (
        Entry("rollcam.host.RollcamError", "common/errors.py", "RollcamError"),
        Entry("rollcam.host.ConfigError", "common/errors.py", "ConfigError"),
        Entry("rollcam.host.SourceError", "common/errors.py", "SourceError"),
        Entry("rollcam.host.DeviceError", "common/errors.py", "DeviceError"),
        Entry("rollcam.host.DeviceNotFoundError", "common/errors.py", "DeviceNotFoundError"),
        Entry("rollcam.host.ProtocolError", "common/errors.py", "ProtocolError"),
        Entry("rollcam.host.MissingDependencyError", "common/errors.py", "MissingDependencyError"),
    )),
)
"""(heading, one line about it, entries) in the order the reference shows them."""

PLUGIN = "host/testing/__init__.py"
"""The pytest plugin (entry point ``pytest11: rollcam``): every fixture it defines is documented."""


def _signature(node: ast.FunctionDef | ast.AsyncFunctionDef, drop_self: bool) -> str:
    args = node.args
    if drop_self and args.posonlyargs:
        args = ast.arguments(args.posonlyargs[1:], args.args, args.vararg, args.kwonlyargs, args.kw_defaults,
                             args.kwarg, args.defaults)
    elif drop_self and args.args:
        args = ast.arguments(args.posonlyargs, args.args[1:], args.vararg, args.kwonlyargs, args.kw_defaults,
                             args.kwarg, args.defaults)
    returns = f" -> {ast.unparse(node.returns)}" if node.returns else ""
    return f"({ast.unparse(args)}){returns}"


def _doc(node: ast.AST) -> str:
    text = ast.get_docstring(node)  # type: ignore[arg-type]
    return text.strip() if text else "(no docstring)"


def _find(tree: ast.Module, name: str) -> ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef:
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and node.name == name:
            return node
    raise LookupError(f"no top-level {name!r}")


def _decorated(node: ast.FunctionDef | ast.AsyncFunctionDef, *names: str) -> bool:
    return any(ast.unparse(d).split("(")[0].split(".")[-1] in names for d in node.decorator_list)


def _members(cls: ast.ClassDef) -> list[str]:
    """The public methods and properties of ``cls``, in source order, as markdown."""
    lines = []
    for node in cls.body:
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        public = not node.name.startswith("_") or node.name in ("__iter__", "__enter__", "__call__")
        if not public or _decorated(node, "setter", "deleter", "overload"):
            continue
        if _decorated(node, "property", "cached_property"):
            head = f"- `.{node.name}`" + (f" -> `{ast.unparse(node.returns)}`" if node.returns else "")
        else:
            head = f"- `.{node.name}{_signature(node, drop_self=not _decorated(node, 'staticmethod'))}`"
        doc = ast.get_docstring(node)
        lines.append(head + (": " + " ".join(doc.split()) if doc else ""))
    return lines


def _fields(cls: ast.ClassDef) -> list[str]:
    """A dataclass's annotated fields with their documentation string, when it has one below it."""
    lines = []
    body = cls.body
    for i, node in enumerate(body):
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and not node.target.id.startswith("_"):
            after = body[i + 1] if i + 1 < len(body) else None
            doc = after.value.value if isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant) \
                and isinstance(after.value.value, str) else ""
            lines.append(f"- `{node.target.id}: {ast.unparse(node.annotation)}`" + (f": {' '.join(doc.split())}"
                                                                                   if doc else ""))
    return lines


def _entry(entry: Entry, tree: ast.Module) -> list[str]:
    node = _find(tree, entry.name)
    if isinstance(node, ast.ClassDef):
        init = next((n for n in node.body if isinstance(n, ast.FunctionDef) and n.name == "__init__"), None)
        bases = ", ".join(ast.unparse(b) for b in node.bases)
        sig = _signature(init, drop_self=True) if init else ""
        lines = [f"### `{entry.public}`", "", f"`class {entry.name}{sig}`" + (f" (bases: `{bases}`)" if bases else ""),
                 "", _doc(node), ""]
        fields, members = _fields(node), _members(node)
        if fields:
            lines += ["Fields:", "", *fields, ""]
        if members:
            lines += ["Methods and properties:", "", *members, ""]
        return lines
    return [f"### `{entry.public}`", "", f"`{entry.name}{_signature(node, drop_self=False)}`", "", _doc(node), ""]


def render(root: Path = ROOT) -> str:
    """docs/api.md's text for the source under ``root``."""
    trees: dict[str, ast.Module] = {}

    def tree(path: str) -> ast.Module:
        if path not in trees:
            trees[path] = ast.parse((root / path).read_text())
        return trees[path]

    out = ["# Python API reference", "",
           "Generated from the docstrings by `python tools/api_docs.py`; do not edit by hand (tests/test_docs.py fails",
           "when this file and the source disagree). Source URIs and their options are in [sources.md](sources.md),",
           "the commands in the README and `rollcam COMMAND --help`.", ""]
    for heading, about, entries in SECTIONS:
        out += [f"## {heading}", "", about, ""]
        for entry in entries:
            out += _entry(entry, tree(entry.path))
    plugin = tree(PLUGIN)
    out += ["## The pytest plugin", "",
            "Installed with rollcam (entry point `pytest11: rollcam`), so these fixtures exist in any test of a",
            "project that has rollcam installed.", "", _doc(plugin), ""]
    for node in plugin.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and _decorated(node, "fixture"):
            out += [f"### fixture `{node.name}`", "", _doc(node), ""]
    return "\n".join(out).rstrip("\n") + "\n"


def main(argv: list[str]) -> int:
    text = render()
    path = ROOT / OUT
    if "--check" in argv:
        if not path.is_file() or path.read_text() != text:
            print(f"{OUT} is stale: run python tools/api_docs.py", file=sys.stderr)
            return 1
        return 0
    path.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
