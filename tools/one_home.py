"""Find each concept written outside its one home (STYLE.md "One home per concept, written down").

`CONCEPTS` lists the concepts that exist once in rollcam, the file(s) that are their home and a pattern that finds
the concept written again: a thread started by hand, an intersection of two boxes, a ``WxH`` split, SplitMix64's
constants... tests/test_one_home.py gates on what this module finds, with an allow-list for API replicas (the
picamera2 stand-in mirrors picamera2's own code) and for copies whose fold is not done yet. Run from the repository
root, ``python tools/one_home.py``, to print every finding and a count per concept (exit 0: the test is the gate).

A pattern is a regular expression matched line by line against code (comments and docstrings skipped, so prose
that names a concept is not a copy of it). Patterns are deliberately narrow: each finds the way the concept was
actually written twice in this tree, and the checker's own tests show each one firing on a made-up source.
"""

from __future__ import annotations

import ast
import io
import re
import sys
import tokenize
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

CODE = ("common", "sim", "firmware", "emu", "host", "benchmarks")
"""The package's layers (DESIGN.md): the folders whose modules `scope="code"` concepts look at."""
TESTS = ("tests",)


@dataclass(frozen=True)
class Concept:
    """A concept that has one home: its name, the home file(s), what finds a copy, and where to look."""

    name: str
    homes: tuple[str, ...]
    pattern: str
    scope: str = "code"  # "code": the package's layers; "tests": tests/
    home_api: str = ""  # what to call instead, for the failure message

    def regex(self) -> re.Pattern[str]:
        return re.compile(self.pattern)


CONCEPTS: tuple[Concept, ...] = (
    Concept("threads", ("common/lifecycle.py",),
            r"\bthreading\.Thread\(|\bThread\(target=|^\s*class \w+\((threading\.)?Thread\)",
            home_api="rollcam.common.lifecycle.Worker (start, stop, re-raise on close)"),
    Concept("context managers", ("common/lifecycle.py",), r"\bdef __enter__\(",
            home_api="subclass rollcam.common.lifecycle.Closeable and write close()"),
    Concept("deadlines", ("common/lifecycle.py",), r"\btime\.monotonic\(\)\s*\+",
            home_api="rollcam.common.lifecycle.Deadline"),
    Concept("image encoding", ("sim/codecs.py",), r"\bcv2\.im(en|de)code\(",
            home_api="rollcam.sim.codecs (encode_jpeg, decode ...)"),
    Concept("colour conversion", ("sim/codecs.py", "sim/isp.py"), r"\bcv2\.cvtColor\(",
            home_api="rollcam.sim.codecs / rollcam.sim.isp"),
    Concept("query parsing", ("common/values.py",), r"\bparse_qsl?\(|\.split\(\s*[\"']&[\"']\s*\)",
            home_api="rollcam.common.values.parse_query"),
    Concept("WxH parsing", ("common/values.py",), r"\.(split|partition)\(\s*[\"'][xX][\"']\s*\)",
            home_api="rollcam.common.values.parse_size / box_size"),
    Concept("integer parsers", ("common/values.py",), r"\bdef (\w*_)?int\(",
            home_api="rollcam.common.values.positive_int / non_negative_int / bounded"),
    Concept("boolean words", ("common/values.py",),
            r"[(\[{]\s*[\"'](0|1|on|off|true|false|yes|no)[\"']\s*,\s*[\"'](0|1|on|off|true|false|yes|no)[\"']",
            home_api="rollcam.common.values.parse_bool"),
    Concept("figure writing", ("common/files.py",), r"\.savefig\(",
            home_api="rollcam.common.files.write_figure"),
    Concept("IoU / IoA", ("host/detectors/ops.py",), r"^\s*inter\s*=|\biw \* ih\b",
            home_api="rollcam.host.detectors.ops.iou_matrix / ioa_matrix"),
    Concept("SplitMix64", ("common/mixing.py",), r"(?i)\b0x9E3779B97F4A7C15\b",
            home_api="rollcam.common.mixing (splitmix64, finalise, GOLDEN; sim._rng's numba mix reads them)"),
    Concept("atomic files", ("common/files.py",), r"\bos\.(replace|rename)\(",
            home_api="rollcam.common.files.write_atomic / commit"),
    Concept("YOLO label lines", ("sim/label_formats.py",), r"\bfloat\(\w+\) for \w+ in \w+\.split\(\)",
            home_api="rollcam.sim.label_formats.yolo_lines"),
    Concept("cameras from a CameraSpec", ("firmware/imaging.py", "sim/synthetic.py"), r"\bSyntheticCamera\(",
            home_api="rollcam.firmware.spec.CameraSpec -> firmware.imaging (what emu: builds)"),
    Concept("V4L2 structures", ("emu/v4l2/raw.py",),
            r"^\s*class (V4[lL]2(?!Error\b)\w*|v4l2_\w+|Capability|FmtDesc|PixFormat|MetaFormat|Format|RequestBuffers|"
            r"Buffer|ExportBuffer|TimeCode|Fract|CaptureParm|StreamParm|FrmSize(Enum)?|FrmIval(Enum)?|Input|QueryCtrl|"
            r"QueryExtCtrl|QueryMenu|ExtControls?|Control|EventSubscription|EventCtrl|Event|Selection)\b",
            home_api="rollcam.emu.v4l2.raw (one ctypes declaration per structure, str/fourcc views)"),
    Concept("test waiting", ("tests/helpers.py",), r"\bdef _?wait_(for|until)\(", scope="tests",
            home_api="tests/helpers.py wait_for"),
    Concept("test fake clocks", ("tests/helpers.py",), r"^class \w*Clock\b", scope="tests",
            home_api="tests/helpers.py FakeClock"),
    Concept("test SIGINT harness", ("tests/interrupts.py",),
            r"\bsend_signal\(signal\.SIGINT\)|\bkillpg\(.*SIGINT", scope="tests",
            home_api="tests/interrupts.py"),
)
"""Each concept's one home and the pattern that finds it elsewhere."""


@dataclass(frozen=True)
class Finding:
    """A copy of `concept` at `path:line` (path relative to the repository root), with the line's text."""

    concept: str
    path: str
    line: int
    text: str

    def __str__(self) -> str:
        return f"{self.path}:{self.line}: {self.concept}: {self.text}"


def _prose_lines(source: str) -> set[int]:
    """Line numbers that hold only a comment or a docstring (string statements), which patterns skip."""
    lines: set[int] = set()
    try:
        tree = ast.parse(source)
    except SyntaxError:
        return lines
    for node in ast.walk(tree):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            lines.update(range(node.lineno, (node.end_lineno or node.lineno) + 1))
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT and not tok.line[: tok.start[1]].strip():
            lines.add(tok.start[0])
    return lines


def scan_text(rel: str, source: str, concepts: Iterable[Concept] = CONCEPTS) -> Iterator[Finding]:
    """Each line of the file `rel` (with text `source`) that writes a concept whose home is elsewhere."""
    skip = _prose_lines(source)
    text_lines = source.splitlines()
    for concept in concepts:
        if rel in concept.homes or not _in_scope(rel, concept):
            continue
        regex = concept.regex()
        for number, line in enumerate(text_lines, start=1):
            code = line.split("  #", 1)[0]
            if number not in skip and regex.search(code):
                yield Finding(concept.name, rel, number, line.strip())


def _in_scope(rel: str, concept: Concept) -> bool:
    top = rel.split("/", 1)[0]
    return top in (CODE if concept.scope == "code" else TESTS)


def files(root: Path) -> Iterator[tuple[str, Path]]:
    """(path relative to `root`, path) of every Python file the concepts look at."""
    for folder in (*CODE, *TESTS):
        for path in sorted((root / folder).rglob("*.py")):
            yield path.relative_to(root).as_posix(), path


def scan(root: Path, concepts: Iterable[Concept] = CONCEPTS) -> list[Finding]:
    """Every copy of a concept outside its home under `root`, sorted by concept, file and line."""
    concepts = tuple(concepts)
    found = [f for rel, path in files(root) for f in scan_text(rel, path.read_text(), concepts)]
    order = {c.name: i for i, c in enumerate(concepts)}
    return sorted(found, key=lambda f: (order[f.concept], f.path, f.line))


def counts(found: Iterable[Finding]) -> Counter[str]:
    """Copies per concept."""
    return Counter(f.concept for f in found)


if __name__ == "__main__":
    root = Path(sys.argv[1]) if len(sys.argv) > 1 else Path.cwd()
    found = scan(root)
    for finding in found:
        print(finding)
    tally = counts(found)
    print()
    for concept in CONCEPTS:
        print(f"{tally[concept.name]:4d}  {concept.name}  (home: {', '.join(concept.homes)})")
