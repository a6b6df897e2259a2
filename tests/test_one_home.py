"""One home per concept (STYLE.md): each concept tools/one_home.py lists lives in its home, and a copy anywhere else
fails here unless the allow-list below names its file and says why it may stay: an API replica (the picamera2 and
depthai stand-ins keep their models' own code), something the pattern finds that is not the concept, or a fold not
done yet ("fold pending", with what stops it). An entry that matches nothing fails too, so the list only shrinks.
`python tools/one_home.py` prints every copy and a count per concept.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[1]

PICAMERA2 = "API replica: the picamera2 stand-in keeps picamera2's own {}"
ALLOWED: dict[tuple[str, str], str] = {
    # threads
    ("threads", "host/datasets/executors.py"):
        "a pool worker's parent watchdog: started by the pool's initializer, it lives as long as the worker process "
        "and ends it by os._exit, with no owner to close it or take an error",
    ("threads", "host/shims/picamera2/encoders/h264_encoder.py"): PICAMERA2.format("encoder reader thread"),
    ("threads", "host/shims/picamera2/job.py"): PICAMERA2.format("Job thread"),
    ("threads", "host/shims/picamera2/outputs/ffmpegoutput.py"): PICAMERA2.format("FfmpegOutput watcher"),
    ("threads", "host/shims/picamera2/remote.py"): PICAMERA2.format("remote results thread"),
    # context managers
    ("context managers", "host/shims/picamera2/controls.py"): PICAMERA2.format("Controls context manager"),
    ("context managers", "host/shims/picamera2/picamera2.py"): PICAMERA2.format("Picamera2 context manager"),
    ("context managers", "host/shims/picamera2/remote.py"): PICAMERA2.format("RemoteMappedArray and Pool"),
    ("context managers", "host/shims/picamera2/request.py"): PICAMERA2.format("CompletedRequest and MappedArray"),
    ("context managers", "host/testing/depthai_mock.py"): "API replica: depthai's Device and Pipeline",
    ("context managers", "host/recording/video.py"):
        "VideoWriter's with-block aborts the file on an exception and keeps it otherwise; Closeable's exit cannot tell",
    ("context managers", "host/videocapture.py"):
        "API replica: cv2.VideoCapture opens again after release(), which Closeable's one-way close does not allow",
    # image encoding
    ("image encoding", "benchmarks/mjpeg.py"):
        "what it times is OpenCV's JPEG encoder with each sampling option: the call itself is the subject",
    ("colour conversion", "benchmarks/uvc.py"):
        "what it times the codec table's 4:2:2 kernel against is OpenCV's cvtColor: the call itself is the subject",
    # parsers
    ("query parsing", "host/sources/http.py"): "a Content-Type header's ;-parameters, not a URI query",
    ("integer parsers", "firmware/protocol.py"):
        "the serial protocol's register arguments are decimal or 0x hex and fail as CommandError 102",
    ("boolean words", "benchmarks/flicker.py"): "the lamp states a loop walks through, not a parser",
    # IoU
    ("IoU / IoA", "host/shims/picamera2/devices/imx500/postprocess.py"):
        "API replica: picamera2's imx500 NMS, pixel-inclusive areas as picamera2 computes them",
    ("IoU / IoA", "host/training/loss.py"):
        "a differentiable GIoU loss on torch tensors; the numpy home has no autograd",
    # cameras
    # tests
    ("V4L2 structures", "firmware/controls.py"): "the firmware's control-table row, named Control; no V4L2 structure",
    ("test waiting", "tests/test_one_home.py"): "the checker's own made-up copy (COPIES below)",
    ("test SIGINT harness", "tests/test_one_home.py"): "the checker's own made-up copy (COPIES below)",
}
"""(concept, file) -> why a copy of the concept may stay in that file for now."""


def _tool() -> ModuleType:
    spec = importlib.util.spec_from_file_location("one_home", ROOT / "tools" / "one_home.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("one_home", module)  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def tool() -> ModuleType:
    return _tool()


@pytest.fixture(scope="module")
def found(tool: ModuleType) -> list:
    return tool.scan(ROOT)


def test_each_concept_lives_in_its_home(tool: ModuleType, found: list) -> None:
    homes = {c.name: c for c in tool.CONCEPTS}
    new = [f"{f}\n    use {homes[f.concept].home_api}" for f in found if (f.concept, f.path) not in ALLOWED]
    assert not new, "a concept written outside its home (call the home instead):\n" + "\n".join(new)


def test_the_allow_list_only_names_copies_that_exist(found: list) -> None:
    gone = set(ALLOWED) - {(f.concept, f.path) for f in found}
    assert not gone, f"allowed copies that are gone: drop them from ALLOWED: {sorted(gone)}"


def test_every_home_exists_and_every_allowed_concept_is_listed(tool: ModuleType) -> None:
    names = {c.name for c in tool.CONCEPTS}
    assert {concept for concept, _ in ALLOWED} <= names
    assert all((ROOT / home).is_file() for c in tool.CONCEPTS for home in c.homes)


# The checker itself, on made-up sources: each pattern must find the copy it is for, and skip prose and homes.

COPIES = {
    "threads": "import threading\nt = threading.Thread(target=print, daemon=True)\n",
    "context managers": "class A:\n    def __enter__(self):\n        return self\n",
    "deadlines": "import time\nend = time.monotonic() + 5\n",
    "image encoding": "import cv2\nok, buf = cv2.imencode('.png', img)\n",
    "colour conversion": "import cv2\ng = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)\n",
    "query parsing": "from urllib.parse import parse_qsl\nq = dict(parse_qsl(text))\n",
    "WxH parsing": "w, h = (int(v) for v in text.split('x'))\n",
    "integer parsers": "def _int(text):\n    return int(text)\n",
    "boolean words": "on = text not in ('0', 'off', 'false')\n",
    "figure writing": "fig.savefig(buf, format='png')\n",
    "IoU / IoA": "def overlap(a, b):\n    inter = w * h\n    return inter / (area_a + area_b - inter)\n",
    "SplitMix64": "x = (x + 0x9e3779b97f4a7c15) & MASK\n",
    "atomic files": "import os\nos.replace(tmp, path)\n",
    "YOLO label lines": "vals = [float(v) for v in line.split()]\n",
    "cameras from a CameraSpec": "cam = SyntheticCamera(sensor, scene, size=(64, 48))\n",
    "V4L2 structures": "import ctypes\nclass PixFormat(ctypes.Structure):\n    _fields_ = []\n",
    "test waiting": "def wait_for(predicate, timeout_s=5):\n    pass\n",
    "test fake clocks": "class FakeClock:\n    t = 0\n",
    "test SIGINT harness": "import signal\nproc.send_signal(signal.SIGINT)\n",
}


@pytest.mark.parametrize("concept", sorted(COPIES))
def test_the_checker_finds_a_copy_of_each_concept(tool: ModuleType, concept: str) -> None:
    spec = next(c for c in tool.CONCEPTS if c.name == concept)
    where = "tests/test_x.py" if spec.scope == "tests" else "host/x.py"
    found = {f.concept for f in tool.scan_text(where, COPIES[concept])}
    assert concept in found
    assert not [f for f in tool.scan_text(spec.homes[0], COPIES[concept]) if f.concept == concept]  # its home


def test_every_concept_has_a_made_up_copy(tool: ModuleType) -> None:
    assert {c.name for c in tool.CONCEPTS} == set(COPIES)


def test_the_checker_finds_a_thread_subclass(tool: ModuleType) -> None:
    source = "import threading\n\n\nclass Reader(threading.Thread):\n    pass\n"
    assert [(f.concept, f.line) for f in tool.scan_text("benchmarks/x.py", source)] == [("threads", 4)]


def test_prose_and_comments_are_not_copies(tool: ModuleType) -> None:
    source = ('"""A docstring naming threading.Thread( and fig.savefig(buf)."""\n'
              "# a comment: os.replace(a, b)\n"
              "x = 1  # trailing: 0x9E3779B97F4A7C15\n")
    assert list(tool.scan_text("host/x.py", source)) == []


def test_a_scan_of_a_made_up_tree_fails_the_gate(tool: ModuleType, tmp_path: Path) -> None:
    (tmp_path / "emu").mkdir()
    (tmp_path / "emu" / "bad.py").write_text("tensors = value not in ('0', 'off', 'false', '')\n")
    (tmp_path / "common").mkdir()
    (tmp_path / "common" / "values.py").write_text("TRUE_WORDS = ('1', 'on', 'true', 'yes')\n")
    found = tool.scan(tmp_path)
    assert [(f.concept, f.path, f.line) for f in found] == [("boolean words", "emu/bad.py", 1)]
