"""The ``file:`` source: footage replayed as GS Frames, or composed into RS Frames as the study did."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np
import pytest
from rollcam.common.errors import SourceError
from rollcam.host.sources import open_camera
from rollcam.sim.compose import compose_rs, compose_stream
from rollcam.sim.footage import Footage
from rollcam.sim.hwconfig import load_sensor
from rollcam.sim.synthetic import resolve_settings
from rollcam.sim.timing import NS_PER_S, Readout

H_PX, W_PX = 48, 80
FPS = 3000
N_FRAMES = 200  # 66.3 ms of footage: two RS frames at 30 fps with a 9.6 ms readout
LINE_NS = 200_000


def scene_bgr(t_ns: int, height: int = H_PX, width: int = W_PX) -> np.ndarray:
    """A textured background with a bright bar sliding right at 1000 px/s, BGR uint8."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    bg = 80 + 40 * np.sin(x / 5.0) * np.cos(y / 7.0)
    x0 = 5 + 1000.0 * t_ns / NS_PER_S
    bar = np.clip(np.minimum(x + 1, x0 + 12) - np.maximum(x, x0), 0, 1)
    gray = (1 - bar) * bg + bar * (200 + 30 * np.sin(y / 3.0))
    return np.clip(np.rint(np.stack([gray, 0.7 * gray + 30, 255 - gray], -1)), 0, 255).astype(np.uint8)


def frame_time_ns(k: int, fps: int = FPS) -> int:
    return round(k * NS_PER_S / fps)


@pytest.fixture(scope="module")
def png_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("png_footage")
    for k in range(N_FRAMES):
        assert cv2.imwrite(str(folder / f"f{k}.png"), scene_bgr(frame_time_ns(k)))
    return folder


@pytest.fixture(scope="module")
def mp4_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("video") / "clip.mp4"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 240, (W_PX, H_PX))
    if not writer.isOpened():
        pytest.skip("this OpenCV build cannot write mp4v")
    for k in range(12):
        writer.write(scene_bgr(frame_time_ns(k, 240)))
    writer.release()
    return path


# ---- global-shutter replay --------------------------------------------------------------------------------
def test_folder_replays_as_global_shutter_bgr_frames(png_dir: Path) -> None:
    with open_camera(f"file:{png_dir}?fps={FPS}&frames=5") as cam:
        frames = list(cam)
        assert cam.info()["shutter"] == "global" and not cam.supports_pairs
    assert [f.sequence for f in frames] == list(range(5))
    for k, f in enumerate(frames):
        np.testing.assert_array_equal(f.data, scene_bgr(frame_time_ns(k)))  # PNG is lossless: BGR comes back
        assert (f.shutter, f.line_time_ns, f.exposure_ns, f.format, f.objects) == ("global", 0, 0, "BGR3", None)
        assert f.timestamp_ns == frame_time_ns(k)
        assert f.row_times_ns.tolist() == [frame_time_ns(k)] * H_PX
        assert f.data.flags.writeable


def test_video_replays_every_decoded_frame_in_bgr(mp4_file: Path) -> None:
    cap = cv2.VideoCapture(str(mp4_file))
    decoded = []
    while True:
        ok, img = cap.read()
        if not ok:
            break
        decoded.append(img)
    cap.release()
    with open_camera(f"file:{mp4_file}") as cam:  # frame rate from the container
        frames = list(cam)
    assert len(frames) == len(decoded) == 12
    for k, (f, ref) in enumerate(zip(frames, decoded, strict=True)):
        np.testing.assert_array_equal(f.data, ref)
        assert f.timestamp_ns == frame_time_ns(k, 240)


# ---- rolling-shutter composition ----------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["nearest", "linear", "flow"])
def test_composed_frames_equal_compose_rs(png_dir: Path, method: str) -> None:
    footage = Footage(png_dir, FPS)
    offsets = np.arange(H_PX, dtype=np.int64) * LINE_NS
    with open_camera(f"file:{png_dir}?fps={FPS}&line_time_ns={LINE_NS}&method={method}") as cam:
        frames = list(cam)
        info = cam.info()
    assert len(frames) == 2  # the third frame would start at 66.7 ms, past the footage's end
    assert (info["shutter"], info["line_time_ns"], info["fps"], info["method"]) == ("rolling", LINE_NS, 30.0, method)
    for n, f in enumerate(frames):
        t0 = round(n * NS_PER_S / 30)
        expected_rgb = compose_rs(footage, t0, offsets, method)
        np.testing.assert_array_equal(f.data, expected_rgb[..., ::-1])
        assert (f.sequence, f.timestamp_ns, f.shutter, f.line_time_ns) == (n, t0, "rolling", LINE_NS)
        assert (f.exposure_ns, f.objects, f.readout, f.format) == (0, None, Readout.TOP_TO_BOTTOM, "BGR3")
        np.testing.assert_array_equal(f.row_times_ns, t0 + offsets)
    footage.close()


def test_sensor_timing_spreads_its_readout_over_the_footage_lines(tmp_path: Path) -> None:
    size = (192, 108)
    for k in range(10):  # 240 fps: 37.5 ms, one letsroll frame (33.3 ms readout)
        cv2.imwrite(str(tmp_path / f"{k:03d}.png"), scene_bgr(frame_time_ns(k, 240), size[1], size[0]))
    timing = resolve_settings(load_sensor("letsroll"), size=size).timing
    with open_camera(f"file:{tmp_path}?fps=240&sensor=letsroll&method=linear&readout=bt") as cam:
        frames = list(cam)
        assert cam.info()["fps"] == pytest.approx(30.0)
    assert len(frames) == 1
    f = frames[0]
    assert f.line_time_ns == timing.line_time_ns and f.readout is Readout.BOTTOM_TO_TOP
    expected = next(iter(compose_stream(Footage(tmp_path, 240), timing, "bt", method="linear", n_frames=1)))
    np.testing.assert_array_equal(f.data, expected.data[..., ::-1])
    np.testing.assert_array_equal(f.row_times_ns, expected.line_times_ns)
    assert f.row_times_ns[-1] == 0 and f.row_times_ns[0] == timing.line_offset_ns(size[1] - 1)


def test_read_pair_gives_the_footage_frame_at_the_rs_start(png_dir: Path) -> None:
    with open_camera(f"file:{png_dir}?fps={FPS}&line_time_ns={LINE_NS}&frames=3") as cam, \
            open_camera(f"file:{png_dir}?fps={FPS}&line_time_ns={LINE_NS}") as plain:
        assert cam.supports_pairs
        pairs = []
        while (pair := cam.read_pair()) is not None:
            pairs.append(pair)
        assert len(pairs) == 2
        for n, (gs, rs) in enumerate(pairs):
            k = round(n * FPS / 30)  # footage frame 100 n is at exactly 33.3 n ms
            assert (gs.shutter, gs.sequence, rs.sequence) == ("global", n, n)
            assert gs.timestamp_ns == rs.timestamp_ns == frame_time_ns(k)
            np.testing.assert_array_equal(gs.data, scene_bgr(frame_time_ns(k)))
            np.testing.assert_array_equal(rs.data, plain.read().data)


def test_frames_option_stops_the_stream_and_close_is_idempotent(png_dir: Path) -> None:
    cam = open_camera(f"file:{png_dir}?fps={FPS}&line_time_ns={LINE_NS}&frames=1")
    assert cam.read() is not None and cam.read() is None
    cam.close()
    cam.close()
    with pytest.raises(SourceError, match="closed"):
        cam.read()


def test_fractional_footage_rate(png_dir: Path) -> None:
    with open_camera(f"file:{png_dir}?fps=30000/1001&frames=3") as cam:
        stamps = [f.timestamp_ns for f in cam]
    assert stamps == [round(k * Fraction(1001, 30000) * NS_PER_S) for k in range(3)]


# ---- errors -------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("query", "match"),
    [
        ("?fps=3000&colour=red", "unknown option"),
        ("?fps=abc", "fps"),
        ("?fps=0", "fps"),
        ("?fps=3000&line_time_ns=fast", "line_time_ns"),
        ("?fps=3000&line_time_ns=-5", "line_time_ns"),
        ("?fps=3000&line_time_ns=1.5", "line_time_ns"),
        ("?fps=3000&frames=-1", "frames"),
        ("?fps=3000&line_time_ns=200000&out_fps=0", "out_fps"),
        ("?fps=3000&line_time_ns=200000&method=cubic", "method"),
        ("?fps=3000&line_time_ns=200000&sensor=letsroll", "not both"),
        ("?fps=3000&sensor=nosuchsensor", "sensor"),
        ("?fps=3000&method=linear", "line_time_ns= or sensor="),
        ("?fps=3000&line_time_ns=200000&readout=sideways", "readout"),
        ("?fps=3000&line_time_ns=200000&flow_preset=slowest&method=flow", "flow_preset"),
        ("?fps=3000&line_time_ns=2000000", "longer than the frame period"),
        ("?fps=30000&line_time_ns=200000", "too short for one rolling-shutter frame"),
        ("", "fps="),
    ],
)
def test_bad_options_name_the_problem(png_dir: Path, query: str, match: str) -> None:
    with pytest.raises(SourceError, match=match):
        open_camera(f"file:{png_dir}{query}")


def test_missing_path_and_empty_target(tmp_path: Path) -> None:
    with pytest.raises(SourceError, match="no such footage"):
        open_camera(f"file:{tmp_path / 'nothing.mp4'}")
    with pytest.raises(SourceError, match="name a video"):
        open_camera("file:")
    with pytest.raises(SourceError, match="no footage frames"):
        open_camera(f"file:{tmp_path}?fps=30")
