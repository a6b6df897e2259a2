"""The examples in README.md and docs/*.md run as written, and docs/architecture.md lists exactly the modules.

Every fenced block in the documentation says what it is in its info string:

- ```` ```sh ```` and ```` ```python ```` are run: each document's blocks in order, in one temporary folder per
  document, shell blocks with ``bash -euo pipefail`` and the venv's ``rollcam`` first on PATH, Python blocks as
  scripts of this interpreter. A block fails the test when it exits non-zero.
- ```` ```sh slow ```` / ```` ```python slow ```` run only with ``pytest -m slow`` (minutes of work).
- ```` ```sh norun ```` / ```` ```python norun ```` are not run here (they need root, hardware, a cluster, the
  network, or hours). Their ``rollcam`` command lines are still checked against ``--help``: the command exists
  and takes every ``--flag`` used; Python ones must compile.
- Anything else (```` ```text ````, ```` ```json ````, ```` ```console ````) is output or a layout, not a command.
  A fence without an info string is an error, so nothing is left unrun by accident.
"""

from __future__ import annotations

import importlib
import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
BIN = Path(sys.executable).parent
RUN_KINDS = {"sh", "python"}
SHOWN_KINDS = {"text", "json", "console", "yaml"}
FLAGS = {"norun", "slow"}
BLOCK_TIMEOUT_S = 600
FENCE = re.compile(r"^```([^\n`]*)\n(.*?)^```[ \t]*$", re.M | re.S)
PACKAGES = ("common", "sim", "firmware", "emu", "host", "benchmarks")


@dataclass(frozen=True)
class Block:
    doc: Path
    line: int
    kind: str
    flags: frozenset[str]
    code: str

    @property
    def where(self) -> str:
        return f"{self.doc.relative_to(ROOT)}:{self.line}"


def blocks(doc: Path) -> list[Block]:
    text = doc.read_text()
    found = []
    for m in FENCE.finditer(text):
        words = m.group(1).split()
        kind = words[0] if words else ""
        found.append(Block(doc, text.count("\n", 0, m.start()) + 1, kind, frozenset(words[1:]), m.group(2)))
    return found


ALL = [b for doc in DOCS for b in blocks(doc)]
RUN = [b for b in ALL if b.kind in RUN_KINDS and "norun" not in b.flags]
NORUN = [b for b in ALL if b.kind in RUN_KINDS and "norun" in b.flags]


def test_every_block_says_what_it_is() -> None:
    bad = [f"{b.where}: ```{' '.join([b.kind, *sorted(b.flags)])}" for b in ALL
           if b.kind not in RUN_KINDS | SHOWN_KINDS or (b.flags - FLAGS) or (b.flags and b.kind not in RUN_KINDS)]
    assert not bad, "fences need an info string: sh or python [norun|slow], or text/json/console/yaml:\n" + \
        "\n".join(bad)
    assert len(RUN) >= 20  # the parser found the examples
    unpaired = [doc.relative_to(ROOT).as_posix() for doc in DOCS
                if sum(line.startswith("```") for line in doc.read_text().splitlines()) != 2 * len(blocks(doc))]
    assert not unpaired, f"a fence line that opens or closes no block (text after a closing ```?): {unpaired}"


@pytest.fixture(scope="module")
def workdirs(tmp_path_factory: pytest.TempPathFactory) -> dict[Path, Path]:
    return {doc: tmp_path_factory.mktemp(doc.stem) for doc in DOCS}


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = f"{BIN}{os.pathsep}{env.get('PATH', '')}"
    env.pop("PYTHONPATH", None)
    return env


@pytest.mark.parametrize("block", [pytest.param(b, id=b.where, marks=[pytest.mark.slow] if "slow" in b.flags else [])
                                   for b in RUN])
def test_example_runs(block: Block, workdirs: dict[Path, Path]) -> None:
    cwd = workdirs[block.doc]
    if block.kind == "sh":
        cmd = ["bash", "-euo", "pipefail", "-c", block.code]
    else:
        script = cwd / f"_block_{block.line}.py"
        script.write_text(block.code)
        cmd = [sys.executable, str(script)]
    res = subprocess.run(cmd, cwd=cwd, env=_env(), capture_output=True, text=True, timeout=BLOCK_TIMEOUT_S,
                         stdin=subprocess.DEVNULL, check=False)
    assert res.returncode == 0, (f"{block.where} exited {res.returncode}\n--- block\n{block.code}"
                                 f"--- stdout\n{res.stdout[-3000:]}\n--- stderr\n{res.stderr[-3000:]}")


def _rollcam_lines(code: str) -> list[list[str]]:
    """Each ``rollcam ...`` command of a shell block, as words (continuations joined, comments dropped)."""
    lines = []
    for line in code.replace("\\\n", " ").splitlines():
        for part in re.split(r"&&|;|\|", line):
            try:
                words = shlex.split(part, comments=True)
            except ValueError:
                continue
            words = [w for w in words if w not in ("sudo",)]
            if words and words[0] == "rollcam":
                lines.append(words[1:])
    return lines


@pytest.mark.parametrize("block", [pytest.param(b, id=b.where) for b in NORUN])
def test_unrun_example_matches_the_cli(block: Block) -> None:
    if block.kind == "python":
        compile(block.code, block.where, "exec")
        return
    for words in _rollcam_lines(block.code):
        command = words[:1]
        help_text = _help(command, block)
        subcommands = _subcommands(help_text)
        if subcommands:
            assert len(words) > 1 and words[1] in subcommands, \
                f"{block.where}: 'rollcam {' '.join(words[:2])}': no such subcommand (one of {sorted(subcommands)})"
            command = words[:2]
            help_text = _help(command, block)
        own = words[:words.index("--")] if "--" in words else words  # after "--": another program's flags
        for flag in (w.split("=")[0] for w in own if w.startswith("--")):
            assert re.search(rf"{re.escape(flag)}\b", help_text), \
                f"{block.where}: 'rollcam {' '.join(command)}' has no {flag}"


def _subcommands(help_text: str) -> set[str]:
    """The subcommands a ``--help`` text lists (``usage: rollcam bench [-h] STUDY ...``), or none."""
    if not re.search(r" \.\.\.\s*$", help_text.split("\n\n")[0]):
        return set()
    return set(re.findall(r"^    ([\w-]+)(?: |$)", help_text, re.M))  # argparse indents choices by four


def _help(command: list[str], block: Block) -> str:
    res = subprocess.run([str(BIN / "rollcam"), *command, "--help"], capture_output=True, text=True, env=_env(),
                         timeout=120, check=False)
    assert res.returncode == 0, f"{block.where}: 'rollcam {' '.join(command)} --help' failed: {res.stderr[-2000:]}"
    return res.stdout


def _tree_modules() -> set[str]:
    return {p.relative_to(ROOT).as_posix() for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")
            if "__pycache__" not in p.parts}


def _table_modules() -> set[str]:
    text = (ROOT / "docs" / "architecture.md").read_text()
    rows = [line for line in text.splitlines() if line.startswith("|")]
    pattern = rf"`((?:{'|'.join(PACKAGES)})/[\w/]+\.py)`"
    return {m for row in rows for m in re.findall(pattern, row.split("|")[1])}


def test_architecture_module_table_lists_exactly_the_modules() -> None:
    tree, table = _tree_modules(), _table_modules()
    missing, extra = sorted(tree - table), sorted(table - tree)
    assert not missing and not extra, (
        f"docs/architecture.md's module tables are out of date.\n  not listed: {missing}\n  listed but absent: {extra}")


FEATURES = ("In-sensor", "IMU", "Rolling-shutter correction", "Faults", "Flicker", "Footage")
"""Features issue 38 asks the index to map, at the least (a row's name starts with one)."""


def _feature_index(text: str) -> dict[str, tuple[str, set[str]]]:
    """docs/architecture.md's feature index: feature -> (path pattern, modules listed)."""
    section = text.split("## Features across subsystems", 1)[1].split("\n## ", 1)[0]
    index = {}
    for line in section.splitlines():
        cells = [c.strip() for c in re.split(r"(?<!\\)\|", line)[1:-1]]
        if len(cells) != 3 or cells[0] in ("Feature", "---"):
            continue
        pattern = cells[1].strip("`").replace("\\|", "|")
        index[cells[0]] = (pattern, set(re.findall(r"`([\w/]+\.py)`", cells[2])))
    return index


def _feature_index_problems(text: str, tree: set[str]) -> list[str]:
    index = _feature_index(text)
    problems = [f"no row for {name!r}" for name in FEATURES if not any(f.startswith(name) for f in index)]
    for feature, (pattern, listed) in index.items():
        if absent := sorted(listed - tree):
            problems.append(f"{feature}: listed but absent: {absent}")
        if unlisted := sorted(m for m in tree - listed if re.search(pattern, m)):
            problems.append(f"{feature}: its pattern {pattern!r} finds modules it does not list: {unlisted}")
    return problems


def test_feature_index_lists_each_features_modules() -> None:
    text = (ROOT / "docs" / "architecture.md").read_text()
    problems = _feature_index_problems(text, _tree_modules())
    assert not problems, "docs/architecture.md's feature index is out of date:\n  " + "\n  ".join(problems)


def test_feature_index_notices_a_new_module_and_a_gone_one() -> None:
    text = (ROOT / "docs" / "architecture.md").read_text()
    tree = _tree_modules()
    assert _feature_index(text)["Flicker ([flicker.md](flicker.md))"][0] == "flicker"
    new = _feature_index_problems(text, tree | {"emu/http/flicker_stats.py"})
    assert new == ["Flicker ([flicker.md](flicker.md)): its pattern 'flicker' finds modules it does not list: "
                   "['emu/http/flicker_stats.py']"]
    gone = _feature_index_problems(text, tree - {"sim/rscorrect.py"})
    assert any("listed but absent: ['sim/rscorrect.py']" in p for p in gone), gone


MACHINE_PATH = re.compile(r"(?<![\w.~/-])/(?:work|root|home|Users)/[\w.-]+")
"""An absolute path of a developer's machine (``/work/x``, ``/root/x``, ``/home/me``): no file of the repository
should hold one; a reader's machine has none of them."""


def _tracked_text_files() -> list[Path]:
    try:
        names = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True,
                               timeout=60).stdout.decode().split("\0")
    except (OSError, subprocess.SubprocessError):
        pytest.skip("needs a git checkout to list the repository's files")
    return [ROOT / name for name in names if name and (ROOT / name).is_file()]


def test_no_file_holds_a_path_of_a_developers_machine() -> None:
    bad = []
    for path in _tracked_text_files():
        if path == Path(__file__).resolve():
            continue  # its own examples below
        data = path.read_bytes()
        if b"\0" in data[:8192]:
            continue  # binary: images, models
        text = data.decode(errors="replace")
        bad += [f"{path.relative_to(ROOT)}:{text.count(chr(10), 0, m.start()) + 1}: {m.group()}"
                for m in MACHINE_PATH.finditer(text)]
    assert not bad, "paths of a developer's machine (use a relative path or a placeholder):\n" + "\n".join(bad)


def test_machine_paths_are_recognised() -> None:
    found = MACHINE_PATH.findall("--out /work/study/x, ~/data, /home/ann/x, https://x.org/work/y, /tmp/a, /root/.cache")
    assert found == ["/work/study", "/home/ann", "/root/.cache"]


def test_relative_links_resolve() -> None:
    bad = [f"{doc.relative_to(ROOT)}: {target}" for doc in DOCS
           for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", doc.read_text())
           if "://" not in target and not (doc.parent / target).exists()]
    assert not bad, bad


def _anchors(doc: Path) -> set[str]:
    """The fragment ids of a Markdown page's headings, as GitHub makes them (repeats get -1, -2, ...)."""
    text = FENCE.sub("", doc.read_text())  # a '# comment' in a code block is no heading
    seen: dict[str, int] = {}
    for heading in re.findall(r"^#{1,6} +(.+?) *#* *$", text, re.M):
        slug = re.sub(r"[^\w\- ]", "", heading.lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        if n:
            seen[f"{slug}-{n}"] = 1
    return set(seen)


def test_links_to_sections_find_them() -> None:
    bad = []
    for doc in DOCS:
        for target, fragment in re.findall(r"\]\(([^)#\s]*)#([^)\s]+)\)", doc.read_text()):
            page = (doc.parent / target) if target else doc
            if "://" not in target and page.suffix == ".md" and fragment not in _anchors(page):
                bad.append(f"{doc.relative_to(ROOT)}: {target}#{fragment}")
    assert not bad, f"links to sections that do not exist: {bad}"


def _table_after(doc: Path, heading: str) -> dict[str, list[str]]:
    """The first table under ``heading`` in ``doc``: first cell's code name -> the other cells."""
    lines = doc.read_text().splitlines()
    start = lines.index(heading)
    rows: dict[str, list[str]] = {}
    for line in lines[start + 1:]:
        if line.startswith("|"):
            cells = [c.strip() for c in line.strip("|").split(" | ")]
            name = re.fullmatch(r"`(\w+)`", cells[0])
            if name:
                assert name.group(1) not in rows, f"{doc.name}: {name.group(1)} listed twice"
                rows[name.group(1)] = cells[1:]
        elif rows:
            break
    return rows


def test_emu_option_table_is_the_firmware_option_table() -> None:
    from rollcam.firmware.options import OPTIONS, as_text
    from rollcam.host.sources.emu import SOURCE_OPTIONS

    rows = _table_after(ROOT / "docs" / "sources.md", "### Options of `emu:`")
    known = set(OPTIONS) | SOURCE_OPTIONS
    assert set(rows) == known, (f"docs/sources.md's emu: options differ from firmware/options.py: not listed "
                                f"{sorted(known - set(rows))}, listed but unknown {sorted(set(rows) - known)}")
    for name, option in OPTIONS.items():
        default = rows[name][0]
        if option.default is None:  # decided by the sensor or the format: said in words, not as a value
            assert not default.startswith("`"), f"{name}: the table has no default value, the doc says {default}"
        else:
            want = f"`{as_text(option.default)}`"
            assert default.split(" ")[0] == want, f"{name}: default {want} in firmware/options.py, {default} in the doc"


def _api_docs():
    import importlib.util

    spec = importlib.util.spec_from_file_location("api_docs", ROOT / "tools" / "api_docs.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("api_docs", module)  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def test_public_names_of_rollcam_host_are_their_modules_own() -> None:
    # The documented import path of each entry point stays `rollcam.host.NAME` wherever its module lives.
    import rollcam.host as host

    for name, where in host.PUBLIC.items():
        module = importlib.import_module(f"rollcam.host.{where}")
        assert getattr(host, name) is getattr(module, name), name
        assert getattr(module, name).__module__ == module.__name__, f"{name} is not defined in {module.__name__}"
    with pytest.raises(AttributeError, match="no attribute 'capture'"):
        host.capture  # noqa: B018  (modules are not public names)


def test_api_reference_is_the_docstrings_of_today() -> None:
    """docs/api.md is generated from the source; a docstring or signature changed without regenerating it fails."""
    assert (ROOT / "docs" / "api.md").read_text() == _api_docs().render(ROOT), \
        "docs/api.md is stale: run python tools/api_docs.py"


def test_api_reference_notices_a_changed_docstring(tmp_path: Path) -> None:
    api = _api_docs()
    for entry in {e.path for _, _, entries in api.SECTIONS for e in entries} | {api.PLUGIN}:
        (tmp_path / entry).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / entry).write_text((ROOT / entry).read_text())
    before = api.render(tmp_path)
    frame = tmp_path / "sim" / "frame.py"
    frame.write_text(frame.read_text().replace('"""One captured image and its timing.', '"""One image.'))
    assert api.render(tmp_path) != before and "One image." in api.render(tmp_path)
