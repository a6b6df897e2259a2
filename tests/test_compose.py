"""Rolling-shutter composition from GS footage, checked against an analytic moving scene.

The scene is a textured bar with anti-aliased edges sliding right over a static textured background,
rendered in closed form at any per-row times, so the exact RS frame (every row at its own time) is known.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np
import pytest
from rollcam.common.errors import ConfigError, SourceError
from rollcam.sim.compose import Composer, compose_rs, compose_stream, composition_error
from rollcam.sim.footage import Footage
from rollcam.sim.timing import NS_PER_S, LineTiming

H_PX, W_PX = 96, 160
LINE_NS = 30_000  # a whole number of ns, so footage at line rate / D has frames exactly on line times
SPEED_PX_PER_S = 0.25 / (LINE_NS / NS_PER_S)  # a quarter pixel per line time: 2 px per frame at /8


def render(row_times_ns: np.ndarray, height: int = H_PX, width: int = W_PX) -> np.ndarray:
    """RGB uint8 image whose row r shows the scene at ``row_times_ns[r]`` (area-sampled bar edges)."""
    y = np.arange(height, dtype=np.float64)[:, None]
    x = np.arange(width, dtype=np.float64)[None, :]
    shift_px = SPEED_PX_PER_S * np.asarray(row_times_ns, dtype=np.float64)[:, None] / NS_PER_S
    background = 90 + 40 * np.sin(2 * np.pi * x / 23.0) * np.cos(2 * np.pi * y / 17.0)
    x0 = 30 + shift_px
    coverage = np.clip(np.minimum(x + 1, x0 + 28) - np.maximum(x, x0), 0, 1)
    u = x + 0.5 - shift_px  # texture coordinate that moves with the bar
    bar = 180 + 40 * np.sin(2 * np.pi * u / 41.0 + y / 9.0) + 25 * np.sin(2 * np.pi * u / 17.0 - y / 13.0)
    gray = (1 - coverage) * background + coverage * bar
    rgb = np.stack([gray, 0.8 * gray + 20, 255 - gray], axis=-1)
    return np.clip(np.rint(rgb), 0, 255).astype(np.uint8)


def footage_at(divisor: int, n_frames: int) -> Footage:
    """Footage at line rate / ``divisor``: frame k is the scene at k * divisor line times."""
    step_ns = LINE_NS * divisor
    frames = np.stack([render(np.full(H_PX, k * step_ns)) for k in range(n_frames)])
    return Footage.from_frames(frames, Fraction(NS_PER_S, step_ns))


def row_offsets_ns(n: int = H_PX) -> np.ndarray:
    return np.arange(n, dtype=np.int64) * LINE_NS


# ---- the study's method ---------------------------------------------------------------------------------
def test_at_line_rate_every_method_is_the_study_method() -> None:
    # The study's own numbers: 32,400 fps footage and a 1/32,400 s line time (30,864.197... ns), where the
    # floored line offsets and the rounded frame times differ by up to 1 ns.
    timing = LineTiming(pixel_rate_hz=32_400_000, line_length_pck=1_000, frame_length_lines=H_PX + 12)
    first = 3
    frame_times_ns = [round(k * NS_PER_S / 32_400) for k in range(H_PX + first + 2)]
    frames = [render(np.full(H_PX, t)) for t in frame_times_ns]
    footage = Footage.from_frames(frames, 32_400)
    assert [footage.time_ns(k) for k in range(len(frames))] == frame_times_ns
    offsets = timing.line_offset_ns(np.arange(H_PX))
    assert np.any(footage.time_ns(first) + offsets != footage.times_ns(np.arange(H_PX) + first))
    study = np.stack([frames[first + r][r] for r in range(H_PX)])
    for method in ("nearest", "linear", "flow"):
        out = compose_rs(footage, footage.time_ns(first), offsets, method)
        assert out.dtype == np.uint8
        np.testing.assert_array_equal(out, study, err_msg=method)
    stream = compose_stream(footage, timing, start_ns=footage.time_ns(first), method="flow", n_frames=1)
    np.testing.assert_array_equal(next(iter(stream)).data, study)


@pytest.mark.parametrize("divisor", [8, 64])
def test_below_line_rate_flow_beats_linear_and_nearest(divisor: int) -> None:
    footage = footage_at(divisor, H_PX // divisor + 4)
    t0 = footage.time_ns(1)
    exact = render(t0 + row_offsets_ns())
    err = {m: composition_error(compose_rs(footage, t0, row_offsets_ns(), m), exact)["mean_abs_err_dn"]
           for m in ("nearest", "linear", "flow")}
    # Measured mean |error| in DN (max in brackets), bar moving 0.25 px per line time:
    #   /8  (2 px per footage frame):  nearest 1.045 (166), linear 0.626 (89), flow 0.075 (14)
    #   /64 (16 px per footage frame): nearest 6.85 (162),  linear 7.03 (131), flow 2.68 (125)
    # Flow's residue sits in the occlusion bands at the bar's two edges, as wide as the motion.
    assert err["flow"] < err["linear"] and err["flow"] < err["nearest"]
    assert err["flow"] < (0.15 if divisor == 8 else 3.5)
    if divisor == 8:
        assert err["linear"] < err["nearest"]


def test_nearest_is_a_staircase_and_linear_a_time_blend() -> None:
    footage = footage_at(8, H_PX // 8 + 4)
    t0 = footage.time_ns(1)
    nearest = compose_rs(footage, t0, row_offsets_ns(), "nearest")
    linear = compose_rs(footage, t0, row_offsets_ns(), "linear")
    for r in range(H_PX):
        # Row r lies r/8 frames after frame 1; a tie (r % 8 == 4) goes to the earlier frame.
        k = 1 + r // 8 + (1 if r % 8 > 4 else 0)
        np.testing.assert_array_equal(nearest[r], footage[k][r])
        w = (r % 8) / 8
        a, b = footage[1 + r // 8][r].astype(float), footage[2 + r // 8][r].astype(float)
        np.testing.assert_array_equal(linear[r], np.rint((1 - w) * a + w * b).astype(np.uint8))
    exact = render(t0 + row_offsets_ns())
    row_err = np.abs(nearest.astype(int) - exact.astype(int)).mean(axis=(1, 2))
    assert np.all(row_err[::8] == 0) and row_err[3] > 0  # exact on frame rows, stale in between


@pytest.mark.parametrize(
    "convert",
    [
        lambda f: f[..., 0].astype(np.uint16) * 257,  # 16-bit mono
        lambda f: f[..., :1],  # H x W x 1
        lambda f: f.astype(np.float32) / 255,
        lambda f: np.ascontiguousarray(f[:20, 20:48]),  # smaller than DIS takes unpadded; bar edge
    ],
    ids=["u16", "hw1", "f32", "tiny"],
)
def test_other_dtypes_and_sizes_keep_dtype_and_order(convert) -> None:
    source = footage_at(8, H_PX // 8 + 4)
    footage = Footage.from_frames([convert(source[k]) for k in range(len(source))], source.fps)
    offsets = row_offsets_ns(footage.height)
    t0 = footage.time_ns(1)
    exact = convert(render(t0 + row_offsets_ns()))
    scale = float(np.max(exact)) or 1.0
    errs = {}
    for method, kw in [("nearest", {}), ("linear", {}), ("flow", {}), ("flow", {"flow_margin_px": 4})]:
        out = compose_rs(footage, t0, offsets, method, **kw)
        assert out.dtype == exact.dtype and out.shape == exact.shape
        errs[method, bool(kw)] = composition_error(out, exact)["mean_abs_err_dn"] / scale
    assert errs["flow", False] < errs["linear", False] < errs["nearest", False]
    assert errs["flow", True] < errs["linear", False]


# ---- geometry and errors --------------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["nearest", "linear", "flow"])
def test_column_readout_is_the_transpose(method: str) -> None:
    footage = footage_at(8, W_PX // 8 + 3)
    transposed = Footage.from_frames([footage[k].swapaxes(0, 1) for k in range(len(footage))], footage.fps)
    t0 = footage.time_ns(1)
    rows = compose_rs(footage, t0, row_offsets_ns(), method)
    cols = compose_rs(transposed, t0, row_offsets_ns(), method, by_column=True)
    assert cols.shape == (W_PX, H_PX, 3)
    np.testing.assert_array_equal(cols, rows.swapaxes(0, 1))


def test_times_outside_footage_raise_source_error() -> None:
    footage = footage_at(8, 6)
    with pytest.raises(SourceError, match="outside"):
        compose_rs(footage, footage.time_ns(3), row_offsets_ns(), "linear")
    with pytest.raises(SourceError, match=r"\[-60000"):
        compose_rs(footage, -60_000, row_offsets_ns(), "nearest")
    with pytest.raises(ConfigError, match="one per row"):
        compose_rs(footage, 0, row_offsets_ns(10), "nearest")
    with pytest.raises(ConfigError, match="method"):
        Composer(footage, "cubic")


def test_stream_frames_follow_the_sensor_timing() -> None:
    # Footage at line rate; an RS sensor whose frame is 128 line times (96 active rows) reads 3 frames.
    footage = footage_at(1, 3 * 128 + 10)
    timing = LineTiming(pixel_rate_hz=100_000_000, line_length_pck=3_000, frame_length_lines=128)
    assert timing.line_offset_ns(1) == LINE_NS
    frames = list(compose_stream(footage, timing, "bottom_to_top"))
    assert [f.index for f in frames] == [0, 1, 2]
    for f in frames:
        start = f.index * 128
        assert f.t_start_ns == start * LINE_NS
        expect = np.stack([footage[start + (H_PX - 1 - r)][r] for r in range(H_PX)])  # last row read first
        np.testing.assert_array_equal(f.data, expect)
    with pytest.raises(SourceError):
        list(compose_stream(footage, timing, fps=Fraction(NS_PER_S, 128 * LINE_NS), n_frames=4))
    column_frames = list(compose_stream(footage_at(1, 200), timing, "lr", n_frames=1))
    assert column_frames[0].data.shape == (H_PX, W_PX, 3)


def test_composition_error_reports_mean_and_max() -> None:
    a = np.zeros((2, 2), np.uint8)
    b = np.array([[0, 4], [0, 250]], np.uint8)
    assert composition_error(a, b) == {"mean_abs_err_dn": 63.5, "max_abs_err_dn": 250.0}
    with pytest.raises(ConfigError):
        composition_error(a, b[:1])


# ---- footage ------------------------------------------------------------------------------------------
def test_footage_times_are_exact_closed_form() -> None:
    footage = Footage.from_frames(np.zeros((3, 2, 2), np.uint8), 29.97002997002997)
    assert footage.fps == Fraction(30_000, 1_001)
    k = 77_000_000_000  # far beyond int64-safe k * 1e9 * den
    assert footage.time_ns(k) == round(Fraction(k * NS_PER_S * 1_001, 30_000))
    assert footage.times_ns(np.array([k]))[0] == footage.time_ns(k)
    fast = Footage.from_frames(np.zeros((40, 2, 2), np.uint8), 32_400)
    t = fast.times_ns(np.arange(40))
    probe = np.concatenate([t, t[1:] - 1])
    np.testing.assert_array_equal(fast.index_at_or_before_ns(probe), np.r_[np.arange(40), np.arange(39)])


def _write_png(path: Path, rgb: np.ndarray) -> None:
    assert cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))


def test_folder_of_pngs_loads_in_natural_order(tmp_path: Path) -> None:
    footage = footage_at(8, 14)
    for k in range(14):
        _write_png(tmp_path / f"frame_{k}.png", footage[k])  # frame_10 must sort after frame_9
    (tmp_path / "notes.txt").write_text("not a frame")
    with pytest.raises(SourceError, match="fps"):
        Footage(tmp_path)
    with Footage(tmp_path, fps=footage.fps, cache_frames=2) as disk:
        assert len(disk) == 14 and disk.shape == (H_PX, W_PX, 3)
        for k in (0, 9, 10, 13, 3):
            np.testing.assert_array_equal(disk[k], footage[k])
        assert not disk[0].flags.writeable
        t0 = footage.time_ns(1)
        from_disk = compose_rs(disk, t0, row_offsets_ns(), "linear")
        np.testing.assert_array_equal(from_disk, compose_rs(footage, t0, row_offsets_ns(), "linear"))
    disk.close()  # a second close is harmless
    with pytest.raises(SourceError, match="closed"):
        disk[0]


def test_folder_errors_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(SourceError, match="no footage frames"):
        Footage(tmp_path, fps=30)
    with pytest.raises(SourceError, match="no such"):
        Footage(tmp_path / "missing", fps=30)
    frame = render(np.zeros(H_PX, np.int64))
    _write_png(tmp_path / "a1.png", frame)
    (tmp_path / "a2.png").write_bytes(b"\x89PNG\r\n\x1a\n truncated")
    _write_png(tmp_path / "a3.png", frame[:-1])
    np.save(tmp_path / "a4.npy", frame)
    with Footage(tmp_path, fps=30) as disk:
        np.testing.assert_array_equal(disk[3], frame)
        with pytest.raises(SourceError, match=r"a2\.png.*decode"):
            disk[1]
        with pytest.raises(SourceError, match=r"a3\.png.*first frame"):
            disk[2]


def test_mp4_video_loads_with_container_fps(tmp_path: Path) -> None:
    path = tmp_path / "clip.mp4"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 240.0, (W_PX, H_PX))
    assert writer.isOpened()
    source = footage_at(8, 20)
    for k in range(len(source)):
        writer.write(cv2.cvtColor(source[k], cv2.COLOR_RGB2BGR))
    writer.release()
    with Footage(path) as video:
        assert video.fps == 240 and len(video) == 20 and video.shape == (H_PX, W_PX, 3)
        sequential = [video[k].copy() for k in range(20)]
        for k in (15, 2, 19, 0, 7):  # random access after the cache has moved on
            video._cache.clear()
            np.testing.assert_array_equal(video[k], sequential[k])
        lossy_err = composition_error(sequential[5], source[5])["mean_abs_err_dn"]
        assert lossy_err < 6
        out = compose_rs(video, video.time_ns(2), row_offsets_ns(), "flow")
        assert out.shape == (H_PX, W_PX, 3)
    (tmp_path / "bad.mp4").write_bytes(b"\x00" * 100)
    with pytest.raises(SourceError, match=r"bad\.mp4"):
        Footage(tmp_path / "bad.mp4")
