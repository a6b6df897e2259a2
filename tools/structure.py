"""Read the package's import structure with `ast`: module graph, cycles, private reach, layer direction.

What a reader trips on is a cycle, a reach into another module's private names or a layer imported upwards
(STYLE.md "Structure over size"); tests/test_structure.py gates on what this module finds. Run from the repository
root, `python tools/structure.py`, to print every finding (and exit 0: the test is the gate, this is the report).

Every import statement counts, wherever it sits: at the top, inside a function, under `if TYPE_CHECKING:`. Module
names follow pyproject.toml's package-dir (`sim/render/renderer.py` is `rollcam.sim.render.renderer`); the stand-in
modules under host/shims/ are import roots of their own (`host/shims/picamera2/job.py` is `picamera2.job`).
"""

from __future__ import annotations

import ast
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

LAYERS = ("common", "sim", "firmware", "emu", "host", "benchmarks")
"""DESIGN.md's layers, lowest first: a module may import its own layer and those before it, never those after."""

SHIMS = Path("host") / "shims"
ROOT_PACKAGE = "rollcam"
NOT_CODE = ("hw_configs",)  # package data with an __init__.py; read by every layer, imports nothing


@dataclass(frozen=True)
class Finding:
    """One thing the gate reports: where it is (`path:line`), what kind, and the text that identifies it."""

    path: str
    line: int
    kind: str
    key: str

    def __str__(self) -> str:
        return f"{self.path}:{self.line}: {self.kind}: {self.key}"


@dataclass
class Module:
    """A parsed module: its dotted name, file, whether it is a package `__init__`, and its syntax tree."""

    name: str
    path: Path
    rel: str
    is_package: bool
    tree: ast.Module
    imports: list[tuple[str, int]] = field(default_factory=list)
    """(module imported, line) for every edge to another module of the project."""


def module_name(rel: Path) -> str:
    """The dotted import name of the project file at `rel` (relative to the repository root)."""
    parts = list(rel.with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    if rel.parts[: len(SHIMS.parts)] == SHIMS.parts:
        return ".".join(parts[len(SHIMS.parts):])
    return ".".join([ROOT_PACKAGE, *parts])


def layer_of(name: str) -> str | None:
    """The DESIGN.md layer a module name belongs to (the stand-ins under host/shims/ are host's); None outside."""
    parts = name.split(".")
    if parts[0] != ROOT_PACKAGE:
        return "host"
    return parts[1] if len(parts) > 1 and parts[1] in LAYERS else None


def load(root: Path) -> dict[str, Module]:
    """Every module of the project under `root`, by dotted name, with its imports resolved to project modules."""
    modules: dict[str, Module] = {}
    for folder in (*LAYERS, *NOT_CODE):
        for path in sorted((root / folder).rglob("*.py")):
            rel = path.relative_to(root)
            modules[module_name(rel)] = Module(
                module_name(rel), path, rel.as_posix(), path.name == "__init__.py", ast.parse(path.read_text()))
    for module in modules.values():
        module.imports = list(_edges(module, modules))
    return modules


def _package_of(module: Module) -> str:
    return module.name if module.is_package else module.name.rpartition(".")[0]


def _absolute(module: Module, node: ast.ImportFrom) -> str:
    """The absolute module name a `from ... import` statement reads from."""
    if not node.level:
        return node.module or ""
    base = _package_of(module).split(".")
    base = base[: len(base) - (node.level - 1)]
    return ".".join([*base, node.module] if node.module else base)


def _edges(module: Module, modules: dict[str, Module]) -> Iterator[tuple[str, int]]:
    for node in ast.walk(module.tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name in modules:
                    yield alias.name, node.lineno
        elif isinstance(node, ast.ImportFrom):
            source = _absolute(module, node)
            for alias in node.names:
                target = f"{source}.{alias.name}"
                if target in modules:
                    yield target, node.lineno
                elif source in modules:
                    yield source, node.lineno


def cycles(modules: dict[str, Module]) -> list[list[str]]:
    """Each set of modules that import each other (a strongly connected component of two or more), sorted.

    Only import statements make edges: importing `a.b` also runs `a/__init__.py` first, but that implicit edge does
    not count (else every `__init__` that re-exports a submodule would close a cycle with each of its siblings).
    """
    graph = {name: sorted({target for target, _ in m.imports if target != name}) for name, m in modules.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(start: str) -> None:  # iterative Tarjan: the graph is deep enough to matter for recursion
        work = [(start, iter(graph[start]))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(graph[child])))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))

    for name in sorted(graph):
        if name not in index:
            visit(name)
    return sorted(found)


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def module_aliases(module: Module, modules: dict[str, Module]) -> dict[str, str]:
    """The local names `module` binds to project modules (`import a.b as c`, `from a import b`), by local name."""
    aliases = {}
    for node in ast.walk(module.tree):
        if isinstance(node, ast.ImportFrom):
            source = _absolute(module, node)
            for alias in node.names:
                if f"{source}.{alias.name}" in modules:
                    aliases[alias.asname or alias.name] = f"{source}.{alias.name}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name in modules:
                    aliases[alias.asname or alias.name] = alias.name
    return aliases


def private_imports(modules: dict[str, Module]) -> list[Finding]:
    """Each `from x import _name` and `x._name` read where `x` is another project module.

    A private module (`sim/render/lines.py`) may be imported by the modules of its own package; from outside it, it is
    a reach like any other private name.
    """
    found = []
    for module in modules.values():
        for node in ast.walk(module.tree):
            if isinstance(node, ast.ImportFrom):
                source = _absolute(module, node)
                for alias in node.names:
                    target = f"{source}.{alias.name}"
                    if target in modules:
                        if _private(alias.name) and not _inside(module, source):
                            found.append(Finding(module.rel, node.lineno, "private module", target))
                    elif source in modules and _private(alias.name) and source != module.name:
                        found.append(Finding(module.rel, node.lineno, "private import", target))
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    package, _, leaf = alias.name.rpartition(".")
                    if alias.name in modules and _private(leaf) and not _inside(module, package):
                        found.append(Finding(module.rel, node.lineno, "private module", alias.name))
        aliases = module_aliases(module, modules)
        for node in ast.walk(module.tree):
            if isinstance(node, ast.Attribute) and _private(node.attr):
                owner = _dotted(node.value) or ""
                target = aliases.get(owner, owner if owner in modules else None)
                if target and target != module.name and f"{target}.{node.attr}" not in modules:
                    found.append(Finding(module.rel, node.lineno, "private read", f"{target}.{node.attr}"))
    return sorted(found, key=lambda f: (f.path, f.line, f.key))


def _inside(module: Module, package: str) -> bool:
    """Whether `module` belongs to `package` (itself or below), so the package's private modules are its own."""
    return module.name == package or module.name.startswith(package + ".")


def _dotted(node: ast.expr) -> str | None:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        head = _dotted(node.value)
        return f"{head}.{node.attr}" if head else None
    return None


SELF_NAMES = {"self", "cls", "mcs"}
PUBLIC_UNDERSCORE = {"_replace", "_asdict", "_fields", "_make", "_field_defaults", "_value_", "_name_", "_missing_",
                     "_generate_next_value_", "_fields_", "_pack_", "_anonymous_", "_as_parameter_", "_length_",
                     "_type_", "_b_base_", "_objects", "_exit", "_getframe", "_current_frames"}
"""Underscored names that are the public API of what owns them: namedtuple, enum, ctypes, os._exit, sys._getframe."""


def _reach(node: ast.AST, aliases: dict[str, str], modules: dict[str, Module]) -> bool:
    """Whether `node` reads a private attribute of something other than self/cls, super() or a module."""
    if not (isinstance(node, ast.Attribute) and _private(node.attr)) or node.attr in PUBLIC_UNDERSCORE:
        return False
    value = node.value
    if isinstance(value, ast.Name) and value.id in SELF_NAMES:
        return False
    if isinstance(value, ast.Call) and isinstance(value.func, ast.Name) and value.func.id == "super":
        return False
    owner = _dotted(value) or ""
    return owner not in aliases and owner not in modules  # a module's private name: private_imports reports it


def private_attributes(modules: dict[str, Module]) -> list[Finding]:
    """Each `obj._attr` where `obj` is not `self`/`cls`, `super()` or a project module (those are private reads).

    A chain reports its first reach only: `a._b._c` is one finding, `a._b`; `self._b._c` is one, `self._b._c`.
    """
    found = []
    for module in modules.values():
        aliases = module_aliases(module, modules)
        found += [Finding(module.rel, node.lineno, "private attribute", f"{ast.unparse(node.value)}.{node.attr}")
                  for node in ast.walk(module.tree)
                  if isinstance(node, ast.Attribute) and _reach(node, aliases, modules)
                  and not any(_reach(inner, aliases, modules) for inner in ast.walk(node.value))]
    return sorted(found, key=lambda f: (f.path, f.line, f.key))


def layer_violations(modules: dict[str, Module]) -> list[Finding]:
    """Each import of a higher layer than the importer's (DESIGN.md: benchmarks -> host -> emu -> firmware -> ...)."""
    found = []
    for module in modules.values():
        mine = layer_of(module.name)
        if mine is None:
            continue
        for target, line in module.imports:
            theirs = layer_of(target)
            if theirs is not None and LAYERS.index(theirs) > LAYERS.index(mine):
                found.append(Finding(module.rel, line, f"{mine} imports {theirs}", target))
    return sorted(set(found), key=lambda f: (f.path, f.line, f.key))


def report(root: Path) -> list[str]:
    """Every finding under `root` as printable lines, cycles first."""
    modules = load(root)
    lines = [f"cycle: {' <-> '.join(c)}" for c in cycles(modules)]
    for finder in (private_imports, private_attributes, layer_violations):
        lines += [str(f) for f in finder(modules)]
    return lines


if __name__ == "__main__":
    for text in report(Path(sys.argv[1]) if len(sys.argv) > 1 else Path.cwd()):
        print(text)
