"""The ``rollcam`` command line: capture, demo, list, command registry, exit codes, one-line errors, progress.

Small emulated streams keep these fast; subprocess tests run the installed console script (or
``python -m rollcam.host.cli`` where it is missing) exactly as a user would.
"""

from __future__ import annotations

import importlib.util
import io
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import wait_for
from interrupts import ctrl_c, interrupt
from rollcam.host import SourceError, open_camera
from rollcam.host.cli import main
from rollcam.host.progress import Progress
from rollcam.host.recording.capture import FRAMES_LOG, CaptureInterrupted, capture
from rollcam.host.recording.demo import run_demo
from rollcam.host.sources import CameraSource
from rollcam.sim.frame import Frame
from rollcam.sim.timing import Readout

URI = "emu:letsroll?size=320x180&scene=street&seed=1&speed=fast"
FIELDS = {"sequence", "shutter", "timestamp_ns", "line_time_ns", "exposure_ns", "readout", "width", "height",
          "format", "file", "objects"}
OBJECT_FIELDS = {"id", "class", "box_gs", "box_rs", "visible", "speed_mps"}


def rollcam_cmd() -> list[str]:
    script = Path(sys.executable).parent / "rollcam"
    return [str(script)] if script.exists() else [sys.executable, "-m", "rollcam.host.cli"]


def run(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*rollcam_cmd(), *args], capture_output=True, text=True, cwd=cwd, timeout=300)


def records(out: Path) -> list[dict]:
    lines = (out / FRAMES_LOG).read_text().splitlines()
    return [json.loads(line) for line in lines]


def leftovers(out: Path) -> list[str]:
    return [p.name for p in out.iterdir() if p.name.endswith(".part") or ".part." in p.name]


def test_help_lists_subcommands():
    res = run("--help")
    assert res.returncode == 0, res.stderr
    for cmd in ("demo", "list", "capture", "bench"):
        assert cmd in res.stdout


def test_version_is_the_package_version():
    from importlib.metadata import version

    res = run("--version")
    assert res.returncode == 0 and res.stdout.strip() == f"rollcam {version('rollcam')}", res.stdout + res.stderr


def test_no_command_is_usage_error():
    res = run()
    assert res.returncode == 2
    assert "Traceback" not in res.stderr


def test_capture_both_pairs_same_instant(tmp_path: Path):
    out = tmp_path / "caps"
    res = run("capture", URI, "--frames", "3", "--out", str(out), "--shutter", "both", "--json")
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    assert summary["frames"] == 3 and summary["images"] == 6 and summary["complete"] is True
    assert Path(summary["out"]) == out and summary["seconds"] >= 0
    recs = records(out)
    assert [(r["sequence"], r["shutter"]) for r in recs] == [
        (i, s) for i in range(3) for s in ("global", "rolling")]
    for r in recs:
        assert set(r) >= FIELDS
        assert (r["width"], r["height"]) == (320, 180)
        assert r["file"] == f"{r['sequence']:06d}_{'gs' if r['shutter'] == 'global' else 'rs'}.png"
        img = cv2.imread(str(out / r["file"]), cv2.IMREAD_UNCHANGED)
        assert img is not None and img.shape == (180, 320, 3)
        for o in r["objects"]:
            assert set(o) >= OBJECT_FIELDS
            for key in ("box_gs", "box_rs"):
                assert o[key] is None or (len(o[key]) == 4 and o[key][0] <= o[key][2] and o[key][1] <= o[key][3])
    for gs, rs in zip(recs[::2], recs[1::2], strict=True):
        assert gs["timestamp_ns"] == rs["timestamp_ns"] and gs["exposure_ns"] == rs["exposure_ns"]
        assert gs["line_time_ns"] == 0 and rs["line_time_ns"] > 0
        gs_boxes = {o["id"]: o["box_gs"] for o in gs["objects"]}
        rs_boxes = {o["id"]: o["box_gs"] for o in rs["objects"] if o["box_gs"] is not None}
        assert rs_boxes and rs_boxes == gs_boxes  # the same instant's GS truth, whichever frame carries it
        assert any(o["box_rs"] != o["box_gs"] for o in rs["objects"])  # fast walkers: RS differs
    info = json.loads((out / "capture.json").read_text())
    assert info["source"]["uri"] == URI and info["source"]["width"] == 320
    assert info["command"][:3] == ["rollcam", "capture", URI]
    assert info["complete"] is True and info["frames"] == 3
    assert not leftovers(out)


def test_capture_default_shutter_jpg_and_overwrite(tmp_path: Path):
    out = tmp_path / "c"
    res = run("capture", URI, "--frames", "2", "--out", str(out), "--format", "jpg")
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in out.glob("*.jpg")) == ["000000_rs.jpg", "000001_rs.jpg"]
    assert all(r["shutter"] == "rolling" for r in records(out))

    again = run("capture", URI, "--frames", "1", "--out", str(out))
    assert again.returncode == 2
    assert "rollcam: error:" in again.stderr and "--overwrite" in again.stderr and "Traceback" not in again.stderr
    assert len(records(out)) == 2  # untouched

    (out / "notes.txt").write_text("keep me")
    res = run("capture", URI, "--frames", "1", "--out", str(out), "--overwrite", "--shutter", "global")
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in out.iterdir()) == ["000000_gs.png", "capture.json", "frames.jsonl", "notes.txt"]
    (rec,) = records(out)
    assert rec["shutter"] == "global" and rec["line_time_ns"] == 0


@pytest.mark.parametrize("uri, words", [
    ("emu:nosuchsensor", "no sensor named 'nosuchsensor'"),
    ("bogus:thing", "scheme 'bogus' is not supported"),
    ("emu:letsroll?colour=red", "unknown option"),
    ("emu:letsroll?size=12by7", "size"),
    ("not-a-uri", "is not a URI"),
    ("emu:letsroll?size=160x90&exposure_us=nan", "exposure_us"),
    ("emu:letsroll?size=160x90&exposure_us=inf", "exposure_us"),
    ("emu:letsroll?size=160x90&fps=1e-12", "below the minimum"),
    ("emu:letsroll?size=160x90&seed=-1", "seed"),
    ("emu:letsroll?size=160x90&frames=0", "frames"),
    ("emu:letsroll?size=160x90&start_ns=-5", "start_ns"),
    ("emu:letsroll?size=160x90&ego=rocket", "ego-motion 'rocket'"),
    ("emu:letsroll?size=160x90&gain=0", "gain"),
])
def test_bad_source_is_exit_2_without_traceback(tmp_path: Path, uri: str, words: str):
    res = run("capture", uri, "--frames", "1", "--out", str(tmp_path / "x"))
    assert res.returncode == 2
    assert res.stderr.startswith("rollcam: error:") and words in res.stderr
    assert "Traceback" not in res.stderr
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("frames", ["0", "-3", "ten", "1.5"])
def test_bad_frames_is_exit_2(tmp_path: Path, frames: str):
    res = run("capture", URI, "--frames", frames, "--out", str(tmp_path / "x"))
    assert res.returncode == 2
    assert "--frames" in res.stderr and "Traceback" not in res.stderr


def test_list_json():
    res = run("list", "--json")
    assert res.returncode == 0, res.stderr
    data = json.loads(res.stdout)
    by_name = {s["name"]: s for s in data["emulated"]}
    assert {"letsroll", "imx219", "ov9281"} <= set(by_name)
    lr = by_name["letsroll"]
    assert lr["shutter"] == "rolling" and lr["default_mode"] == "1920x1080" and lr["line_time_ns"] == 30864
    assert lr["fps"] == pytest.approx(30.0) and lr["uri"] == "emu:letsroll"
    assert by_name["ov9281"]["shutter"] == "global"
    for key in ("v4l2", "oak", "usb"):  # each device section lists devices or says why there are none
        assert data[key]["devices"] or data[key]["note"]
    table = run("list")
    assert table.returncode == 0 and "letsroll" in table.stdout and "OAK devices" in table.stdout
    assert res.stderr == table.stderr == ""  # depthai's and OpenCV's own log lines are silenced


def test_bench_lists_one_subcommand_per_study_each_with_json_and_check(capsys):
    from rollcam.benchmarks.studies import STUDIES

    assert list(STUDIES) == ["render", "realism", "detect", "ptc", "sensor", "uvc", "soak", "mjpeg", "dataset", "imu",
                            "view", "preload", "personnet", "flicker", "device", "insensor"]
    with pytest.raises(SystemExit) as exc:
        main(["bench", "--help"])
    assert exc.value.code == 0
    listing = capsys.readouterr().out
    assert all(name in listing for name in STUDIES)
    for name in STUDIES:
        with pytest.raises(SystemExit):
            main(["bench", name, "--help"])
        text = capsys.readouterr().out
        assert f"rollcam bench {name}" in text and "--json" in text and "--check" in text and "--out" in text


def test_every_command_is_a_module_registered_the_same_way():
    from rollcam.host.commands import COMMANDS

    assert set(COMMANDS) >= {"demo", "list", "capture", "detect", "emulate", "view", "dataset", "eval", "bench"}
    for module_name in COMMANDS.values():
        module = importlib.import_module(module_name)
        assert callable(module.add_parser) and callable(module.run), module_name
    # Building every parser imports none of the heavy or optional packages: --help is fast whatever is missing.
    code = ("import sys; from rollcam.host.cli import build_parser; build_parser(); "
            "print(sorted(m for m in ('numpy', 'cv2', 'numba', 'usb', 'serial', 'depthai', 'onnxruntime', 'tqdm') "
            "if m in sys.modules))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0 and res.stdout.strip() == "[]", res.stdout + res.stderr


@pytest.mark.parametrize("argv, words", [
    ([], "the following arguments are required: COMMAND"),
    (["nosuch"], "invalid choice: 'nosuch'"),
    (["list", "--bogus"], "list: unrecognized arguments: --bogus (see 'rollcam list --help')"),
    (["capture", URI, "--out", "x"], "capture: the following arguments are required: --frames"),
    (["capture", URI, "--frames", "0", "--out", "x"], "argument --frames: '0' is invalid: must be an integer >= 1"),
    (["detect", URI, "--detector", "hog", "--iou", "2"], "argument --iou: '2' is invalid: must be a number in (0, 1]"),
    (["detect", URI, "--detector", "hog", "--iou", "0"], "--iou"),
    (["detect", URI, "--detector", "hog", "--min-visible", "5"], "--min-visible: '5' is invalid"),
    (["detect", URI, "--detector", "hog", "--min-height", "-1"], "--min-height"),
    (["demo", "--seconds", "nan"], "--seconds"),
    (["dataset", "--out", "x", "--min-visible", "1.5"], "--min-visible"),
    (["dataset", "--out", "x", "--min-box", "6by16"], "--min-box"),
    (["bench"], "bench: the following arguments are required: STUDY"),
    (["bench", "soak", "--minutes", "-1"], "bench soak: argument --minutes: '-1' is invalid: must be greater than 0"),
    (["bench", "soak", "--cameras", "0"], "bench soak: argument --cameras: '0' is invalid: must be an integer >= 1"),
    (["bench", "soak", "--cameras", "17"], "bench soak: --cameras 17 is not in 2..16 (a rig's cameras)"),
    (["bench", "soak", "--cameras", "2", "--hog"], "--hog applies to the one-camera soak, not to --cameras 2"),
    (["bench", "soak", "--cameras", "2", "--memory"], "bench soak: --memory applies to the one-camera soak"),
    (["bench", "soak", "--cameras", "2", "--rt-priority", "5"], "bench soak: --rt-priority applies to the one-camera"),
    (["bench", "soak", "--cameras", "2", "--sync", "maybe"], "bench soak: --sync 'maybe' is not one of ('hw', 'free')"),
    (["bench", "soak", "--sync", "hw"], "bench soak: --sync needs --cameras N (N >= 2)"),
    (["bench", "soak", "--physics", "off"], "bench soak: --physics needs --cameras N (N >= 2)"),
    (["bench", "soak", "--cameras", "2", "--physics", "maybe"],
     "bench soak: argument --physics: expected one of 1/on/true/yes or 0/off/false/no, got 'maybe'"),
    (["bench", "soak", "--size", "1280by720"], "bench soak: argument --size: size '1280by720' is not WIDTHxHEIGHT"),
    (["bench", "dataset", "--size", "10x"], "bench dataset: argument --size: size '10x' is not WIDTHxHEIGHT"),
    (["bench", "render", "--size", "big"], "--size"),
    (["emulate", "imx219", "--duration", "-1"], "emulate: argument --duration: '-1' is invalid: must be a number >= 0"),
    (["emulate", "imx219", "--quality", "0"], "argument --quality: JPEG quality '0' is not an integer in 1..100"),
    (["emulate", "imx219", "--quality", "101"], "argument --quality: JPEG quality '101' is not"),
    (["emulate", "imx219", "--fps", "fast"], "emulate: argument --fps: 'fast' is invalid: expected a number > 0"),
    (["emulate", "imx219", "--speed", "3x"], "argument --speed: '3x' is invalid: expected static | normal | fast"),
    (["emulate", "imx219", "--usbip", "host"], "emulate: argument --usbip: expected HOST:PORT, got 'host'"),
    (["emulate", "imx219", "--usb-id", "logitech"], "argument --usb-id: 'logitech' is not VID:PID in hex"),
    (["emulate", "imx219", "--usb-id", "10000:1"], "argument --usb-id: VID:PID '10000:1' is out of range"),
])
def test_usage_errors_are_one_error_line_and_exit_2(capsys, argv, words):
    assert main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("rollcam: error: ") and words in lines[0], captured.err
    assert "usage:" not in captured.err and not captured.out


@pytest.mark.parametrize("argv, new", [
    (["--quick"], "rollcam bench render --quick"), (["--hog"], "rollcam bench realism"),
    (["--detect"], "rollcam bench detect"), (["--ptc"], "rollcam bench ptc"),
    (["--ptc", "imx477"], "rollcam bench ptc imx477"), (["--sensor"], "rollcam bench sensor"),
    (["--uvc"], "rollcam bench uvc"), (["--soak", "--minutes", "1"], "rollcam bench soak"),
    (["--dataset", "--size", "10x"], "rollcam bench dataset"),
])
def test_old_bench_flags_name_their_subcommand(capsys, tmp_path: Path, argv, new):
    assert main(["bench", *argv, "--out", str(tmp_path / "b")]) == 2
    captured = capsys.readouterr()
    assert captured.err == f"rollcam: error: bench: {argv[0]} is now {new!r}\n" and not captured.out
    assert not (tmp_path / "b").exists()


def test_emulate_options_are_the_command_modules_and_quality_defaults_to_the_codec_tables():
    from rollcam.common.values import JPEG_QUALITY
    from rollcam.host.cli import build_parser
    from rollcam.sim import codecs

    parser, _ = build_parser()
    args = parser.parse_args(["emulate", "imx219", "--fps", "15", "--serial-number", "X1", "--serial"])
    assert args.quality == JPEG_QUALITY == codecs.JPEG_QUALITY
    assert args.run.__module__ == "rollcam.host.commands.emulate"
    assert (args.http, args.usbip, args.duration) == (None, None, None) and args.serial
    from rollcam.host.commands.emulate import camera_options

    assert camera_options(args) == {"fps": "15", "serial": "X1"}  # text, parsed by the option table as in emu:
    assert parser.parse_args(["emulate", "imx219", "--http", ":0", "--quality", "40"]).http == ("127.0.0.1", 0)


def test_emulate_duration_0_stops_as_soon_as_the_servers_are_up():
    res = run("emulate", "imx219", "--size", "640x480", "--scene", "flat", "--http", "127.0.0.1:0", "--duration", "0",
              "--json")
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["http"]["url"].startswith("http://127.0.0.1:")
    assert "stopped;" in res.stderr


@pytest.mark.parametrize("uri, words", [
    ("opencv:63", "no camera at that index"),
    ("v4l2:/dev/video99", "no device '/dev/video99'"),
    ("http://127.0.0.1:9/stream.mjpg#timeout=1", "cannot connect"),
])
def test_a_camera_that_is_not_there_is_a_device_failure_exit_1(tmp_path: Path, uri: str, words: str):
    res = run("capture", uri, "--frames", "1", "--out", str(tmp_path / "x"))
    assert res.returncode == 1, res.stderr
    # One line: OpenCV's and depthai's own log lines are silenced for the call.
    assert res.stderr.count("\n") == 1 and res.stderr.startswith("rollcam: error:") and words in res.stderr
    assert not (tmp_path / "x").exists()


def test_http_fragment_options_are_parsed_like_any_query(tmp_path: Path):
    res = run("capture", "http://127.0.0.1:9/x#frames=1&frames=9", "--frames", "1", "--out", str(tmp_path / "x"))
    assert res.returncode == 2 and "option 'frames' given twice" in res.stderr  # refused before connecting
    with pytest.raises(SourceError, match="latest=2"):
        open_camera("http://127.0.0.1:9/x#latest=2")


def test_a_missing_optional_package_is_one_line_and_exit_1(monkeypatch, capsys, tmp_path: Path):
    monkeypatch.setitem(sys.modules, "usb", None)  # as if pyusb were not installed
    monkeypatch.setitem(sys.modules, "usb.core", None)
    assert main(["capture", "uvc:1209:0001?backend=emu", "--frames", "1", "--out", str(tmp_path / "x")]) == 1
    err = capsys.readouterr().err
    broken = "an install dependency of rollcam missing from this broken install (pip install pyusb)"
    assert err == f"rollcam: error: the uvc: source needs pyusb, {broken}\n"
    assert main(["bench", "uvc", "--out", str(tmp_path / "b")]) == 1
    assert capsys.readouterr().err == f"rollcam: error: rollcam bench uvc needs pyusb, {broken}\n"
    assert not (tmp_path / "b").exists()


def test_install_hints_follow_pyproject():
    from rollcam.common.errors import MissingDependencyError

    # An extra's package names the extra; an install dependency's says the install is broken; anything else
    # (a user's choice such as the GPU runtime) names its own pip install, quoted for the shell.
    assert str(MissingDependencyError("faster-coco-eval", "eval", "rollcam eval")) == (
        "rollcam eval needs faster-coco-eval (pip install 'rollcam[eval]')")
    assert str(MissingDependencyError("pyserial", feature="x")) == (
        "x needs pyserial, an install dependency of rollcam missing from this broken install (pip install pyserial)")
    assert str(MissingDependencyError("depthai>=3,<4")).endswith("broken install (pip install 'depthai>=3,<4')")
    assert str(MissingDependencyError("onnxruntime-gpu", feature="y")) == (
        "y needs onnxruntime-gpu (pip install onnxruntime-gpu)")


def _install_hints(root: Path) -> list[tuple[str, str | None, str | None]]:
    """(where, package, extra) of every literal ``require(...)`` / ``MissingDependencyError(...)`` call."""
    import ast

    out = []
    for folder in ("common", "host", "emu", "firmware", "sim", "benchmarks"):
        for path in (root / folder).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                name = getattr(getattr(node, "func", None), "id", None)
                if not isinstance(node, ast.Call) or name not in ("require", "MissingDependencyError"):
                    continue
                names = ("module", "package", "extra") if name == "require" else ("package", "extra")
                given = dict(zip(names, node.args, strict=False)) | {k.arg: k.value for k in node.keywords}
                value = {k: v.value for k, v in given.items() if isinstance(v, ast.Constant)}
                package = value.get("package") or value.get("module", "").split(".")[0]
                out.append((f"{path.relative_to(root)}:{node.lineno}", package, value.get("extra")))
    return out


def test_every_install_hint_names_an_extra_that_exists_and_holds_the_package():
    import tomllib

    root = Path(__file__).resolve().parents[1]
    extras = tomllib.loads((root / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    hints = _install_hints(root)
    assert len(hints) >= 8 and {p for _, p, e in hints if e is None} >= {"pyusb", "pyserial", "depthai", "onnxruntime"}
    for where, package, extra in hints:
        if extra is not None:
            held = {re.split(r"[<>=\[;]", r)[0] for r in extras.get(extra, [])}
            assert package.split("[")[0] in held, f"{where}: extra {extra!r} does not hold {package!r}"


def test_no_hand_written_install_hints_outside_the_one_error_type():
    root = Path(__file__).resolve().parents[1]
    offenders = [str(p.relative_to(root)) for folder in ("host", "emu", "firmware", "sim", "benchmarks")
                 for p in (root / folder).rglob("*.py") if "pip install" in p.read_text()]
    assert offenders == []


def test_unknown_argument_is_exit_2():
    res = run("list", "--bogus")
    assert res.returncode == 2 and "--bogus" in res.stderr


def test_demo_writes_video_and_contact_sheet(tmp_path: Path):
    result = run_demo(tmp_path / "demo", seconds=0.2, size=(320, 180), progress=False)
    assert result.frames == 6 and result.pedestrians > 0 and result.mean_shift_px > 0
    cap = cv2.VideoCapture(str(result.video))
    try:
        assert cap.isOpened()
        n = 0
        while True:
            ok, img = cap.read()
            if not ok:
                break
            n += 1
            assert img.shape[1] == 320
    finally:
        cap.release()
    assert n == 6
    sheet = cv2.imread(str(result.contact_sheet))
    assert sheet is not None and sheet.shape[1] > 2 * 320
    assert not leftovers(tmp_path / "demo")


def test_demo_cli(tmp_path: Path):
    res = run("demo", "--out", str(tmp_path / "d"), "--seconds", "0.1", "--size", "320x180")
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "d" / "demo_rs.mp4").stat().st_size > 0
    assert (tmp_path / "d" / "contact_sheet.png").stat().st_size > 0
    assert "pedestrians" in res.stdout and "demo_rs.mp4" in res.stdout


class _InterruptAfter(CameraSource):
    """Delegates to a real source and raises KeyboardInterrupt (as Ctrl-C would) on read number k + 1; or, as
    compiled code Ctrl-C interrupts does (numba), a SystemError raised from it."""

    supports_pairs = True

    def __init__(self, inner: CameraSource, k: int, compiled: bool = False) -> None:
        self.inner, self.k, self.n, self.uri, self.compiled = inner, k, 0, inner.uri, compiled

    def _tick(self) -> None:
        self.n += 1
        if self.n > self.k:
            ctrl_c(self.compiled)

    def read(self) -> Frame | None:
        self._tick()
        return self.inner.read()

    def read_pair(self) -> tuple[Frame, Frame] | None:
        self._tick()
        return self.inner.read_pair()

    def info(self) -> dict:
        return self.inner.info()


@pytest.mark.parametrize("shutter, per_frame, compiled", [(None, 1, False), ("both", 2, False), ("both", 2, True)])
def test_interrupted_capture_keeps_complete_frames(tmp_path: Path, shutter: str | None, per_frame: int,
                                                   compiled: bool):
    k = 3
    out = tmp_path / "cap"
    with open_camera(URI) as inner, pytest.raises(CaptureInterrupted) as exc:
        capture(_InterruptAfter(inner, k, compiled), out, 10, shutter=shutter, progress=False)
    assert isinstance(exc.value, KeyboardInterrupt)
    assert exc.value.result.frames == k and not exc.value.result.complete
    recs = records(out)
    assert len(recs) == k * per_frame
    assert all((out / r["file"]).is_file() for r in recs)
    assert len(list(out.glob("*.png"))) == k * per_frame
    assert not leftovers(out)
    info = json.loads((out / "capture.json").read_text())
    assert info["frames"] == k and info["complete"] is False and info["interrupted"] is True


class _FailingEncode(CameraSource):
    """Pairs whose rolling frame cannot be stored as an image: the pair's GS image must not survive alone."""

    supports_pairs = True
    uri = "test:failing"

    def __init__(self, inner: CameraSource) -> None:
        self.inner = inner

    def read(self) -> Frame | None:
        return self.inner.read()

    def read_pair(self) -> tuple[Frame, Frame] | None:
        gs, rs = self.inner.read_pair()
        if gs.sequence == 1:
            bad = Frame(np.zeros((4, 4, 5), np.uint8), "XXXX", rs.sequence, rs.timestamp_ns, rs.line_time_ns,
                        rs.readout, rs.exposure_ns)
            return gs, bad
        return gs, rs


def test_failed_pair_leaves_no_orphan_image(tmp_path: Path):
    out = tmp_path / "cap"
    with open_camera(URI) as inner, pytest.raises(SourceError):
        capture(_FailingEncode(inner), out, 3, shutter="both", progress=False)
    assert [r["file"] for r in records(out)] == ["000000_gs.png", "000000_rs.png"]
    assert sorted(p.name for p in out.glob("*.png")) == ["000000_gs.png", "000000_rs.png"]


class _NoPairs(CameraSource):
    uri = "test:nopairs"

    def read(self) -> Frame | None:
        return None


def test_both_needs_pairs(tmp_path: Path):
    with pytest.raises(SourceError, match="paired"):
        capture(_NoPairs(), tmp_path / "x", 2, shutter="both")
    assert not (tmp_path / "x").exists()


def test_finite_source_ends_capture_early(tmp_path: Path):
    with open_camera(URI + "&frames=2") as src:
        result = capture(src, tmp_path / "x", 5, progress=False)
    assert result.frames == 2 and not result.complete
    assert len(records(tmp_path / "x")) == 2


def test_progress_is_one_refreshing_line():
    buf = io.StringIO()
    bar = Progress(4, label="capture", stream=buf, enabled=True, unit="frame", min_interval_s=0)
    for done in range(1, 5):
        bar.update(done)
    bar.close()
    bar.close()  # harmless
    text = buf.getvalue()
    assert text.count("\n") == 1 and text.endswith("\n") and text.count("\r") >= 4  # redrawn in place
    assert "capture 4/4" in text and "frame/s" in text and "ETA" in text
    steps = io.StringIO()
    bar = Progress(label="bench realism", stream=steps, enabled=True)
    for i in range(100):
        bar.status(f"frame {i + 1}/100")
    bar.close()
    assert steps.getvalue().count("\n") == 1 and "frame 100/100" in steps.getvalue()  # 100 steps, one line
    quiet = io.StringIO()
    bar = Progress(4, label="x", stream=quiet)  # StringIO is not a TTY: nothing shown by default
    bar.update(1)
    bar.status("step")
    bar.close()
    assert quiet.getvalue() == ""


def test_refused_capture_writes_nothing_so_the_corrected_command_runs(tmp_path: Path):
    out = tmp_path / "raw"
    raw = "emu:imx219?size=160x120&format=pRAA&frames=3"
    res = run("capture", raw, "--frames", "2", "--out", str(out), "--format", "jpg")
    assert res.returncode == 2 and "--format jpg would lose the samples" in res.stderr
    assert not out.exists()  # no folder, no capture.json, no frames.jsonl
    res = run("capture", raw, "--frames", "2", "--out", str(out), "--format", "png")
    assert res.returncode == 0, res.stderr
    assert [r["file"] for r in records(out)] == ["000000_rs.png", "000001_rs.png"]


class _UnknownShutter(CameraSource):
    """Frames of a camera whose shutter is unknown (a webcam through opencv: without sensor=)."""

    uri = "test:webcam"

    def __init__(self) -> None:
        self.n = 0

    def read(self) -> Frame | None:
        self.n += 1
        if self.n > 2:
            return None
        return Frame(np.zeros((8, 8, 3), np.uint8), "BGR3", self.n - 1, self.n * 1000, 0, Readout.TOP_TO_BOTTOM, 0,
                     shutter="unknown")


def test_unknown_shutter_captures_are_named_by_instant_only(tmp_path: Path):
    capture(_UnknownShutter(), tmp_path / "cam", 5, progress=False)
    assert sorted(p.name for p in (tmp_path / "cam").glob("*.png")) == ["000000.png", "000001.png"]
    assert [r["file"] for r in records(tmp_path / "cam")] == ["000000.png", "000001.png"]
    capture(_UnknownShutter(), tmp_path / "cam", 1, overwrite=True, progress=False)  # --overwrite clears them
    assert sorted(p.name for p in (tmp_path / "cam").glob("*.png")) == ["000000.png"]


def test_demo_follows_a_global_shutter_sensor(tmp_path: Path):
    result = run_demo(tmp_path / "gs", seconds=0.05, sensor="ov9281", size=(320, 200), progress=False)
    assert result.shutter == "global" and result.mean_shift_px == 0.0
    assert result.video.name == "demo_gs.mp4" and result.video.stat().st_size > 0
    assert "no rolling-shutter skew" in result.summary() and "RS-GS" not in result.summary()
    sheet = cv2.imread(str(result.contact_sheet))
    assert sheet.shape[1] == 480  # one column of GS tiles, no RS column
    rolling = run_demo(tmp_path / "rs", seconds=0.1, size=(320, 180), progress=False)
    assert rolling.shutter == "rolling" and rolling.video.name == "demo_rs.mp4" and "RS-GS" in rolling.summary()


def test_compile_notice_only_when_the_renderer_cache_is_cold(tmp_path: Path):
    from rollcam.host.commands.compile_notice import NOTICE, notify_if_cold, renderer_cache_cold

    with open_camera("emu:letsroll?size=64x36&frames=1") as src:
        src.read()  # compiled or loaded: numba has it cached now
    assert renderer_cache_cold() is False
    quiet = io.StringIO()
    assert notify_if_cold(quiet) is False and quiet.getvalue() == ""
    code = ("import io; from rollcam.host.commands.compile_notice import notify_if_cold; b = io.StringIO(); "
            "print(notify_if_cold(b), repr(b.getvalue()))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                         env={**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "empty")})
    assert res.stdout.strip() == f"True {NOTICE + chr(10)!r}", res.stdout + res.stderr


@pytest.mark.skipif(os.name != "posix", reason="sends SIGINT")
def test_ctrl_c_exits_130_with_complete_log(tmp_path: Path):
    out = tmp_path / "cap"
    proc = subprocess.Popen([*rollcam_cmd(), "capture", URI, "--frames", "100000", "--out", str(out),
                             "--shutter", "both"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        log = out / FRAMES_LOG
        wait_for(lambda: log.exists() and log.read_text().count("\n") >= 4, 120, "four frames logged")
        _, err = interrupt(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "interrupted" in err
    recs = records(out)
    assert len(recs) >= 4 and len(recs) % 2 == 0
    assert all((out / r["file"]).is_file() for r in recs)
    assert len(list(out.glob("*.png"))) == len(recs)
    assert not leftovers(out)
    assert json.loads((out / "capture.json").read_text())["interrupted"] is True


def test_an_error_raised_from_a_ctrl_c_counts_as_the_interruption() -> None:
    # Compiled code a SIGINT interrupts reports a SystemError caused by the KeyboardInterrupt (numba does).
    from rollcam.common.errors import EXIT_INTERRUPTED, exit_code, is_interrupt

    with pytest.raises(SystemError) as info:
        ctrl_c(compiled=True)
    assert is_interrupt(info.value) and exit_code(info.value) == EXIT_INTERRUPTED
    assert not is_interrupt(SystemError("a bug")) and exit_code(SystemError("a bug")) == 1
