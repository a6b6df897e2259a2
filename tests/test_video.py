"""host/recording/video.py: H.264 yuv420p MP4 that browsers play, checked by an independent demuxer (PyAV), written
atomically."""

from __future__ import annotations

import os
import stat
from fractions import Fraction
from pathlib import Path

import av
import numpy as np
import pytest
from rollcam.common.errors import ConfigError
from rollcam.host.detectors import PERSON, Detections
from rollcam.host.detectors.live import VIDEO, run_detect
from rollcam.host.recording.demo import run_demo
from rollcam.host.recording.video import VideoWriter


def probe(path: Path) -> dict:
    """What a player sees: codec, pixel format, size, frame rate, decoded frame count, and the frames."""
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        ctx = stream.codec_context
        frames = [f.to_ndarray(format="bgr24") for f in container.decode(stream)]
        return {"codec": ctx.name, "pix_fmt": ctx.pix_fmt, "size": (stream.width, stream.height),
                "fps": Fraction(stream.average_rate), "frames": frames, "format": container.format.name}


def moving_bar(i: int, w: int, h: int) -> np.ndarray:
    img = np.full((h, w, 3), 40, np.uint8)
    img[:, (7 * i) % (w - 16):(7 * i) % (w - 16) + 16] = (0, 0, 230)  # a red bar moving right
    return img


def test_writes_h264_yuv420p_with_frame_count_size_and_fps(tmp_path: Path) -> None:
    path = tmp_path / "clip.mp4"
    with VideoWriter(path, 30.0143, (320, 180)) as writer:
        for i in range(25):
            writer.write(moving_bar(i, 320, 180))
    info = probe(path)
    assert info["codec"] == "h264" and info["pix_fmt"] == "yuv420p" and "mp4" in info["format"]
    assert info["size"] == (320, 180) and len(info["frames"]) == 25
    assert abs(float(info["fps"]) - 30.0143) < 1e-3
    # the pictures survive: the bar is where it was drawn, within H.264's loss
    got, want = info["frames"][10].astype(int), moving_bar(10, 320, 180).astype(int)
    assert np.abs(got - want).mean() < 4
    assert not [p for p in os.listdir(tmp_path) if p != "clip.mp4"]


def test_moov_atom_is_at_the_front_for_progressive_playback(tmp_path: Path) -> None:
    path = tmp_path / "clip.mp4"
    with VideoWriter(path, 25, (64, 48)) as writer:
        for i in range(3):
            writer.write(moving_bar(i, 64, 48))
    head = path.read_bytes()[:4096]
    assert 0 <= head.find(b"moov") < head.find(b"mdat")


def test_odd_sizes_are_padded_to_even(tmp_path: Path) -> None:
    path = tmp_path / "odd.mp4"
    with VideoWriter(path, 10, (65, 33)) as writer:
        for i in range(4):
            writer.write(moving_bar(i, 65, 33))
    assert writer.encoded_size == (66, 34)
    info = probe(path)
    assert info["size"] == (66, 34) and len(info["frames"]) == 4 and info["pix_fmt"] == "yuv420p"


def test_nothing_is_left_under_the_final_name_until_close_and_nothing_after_abort(tmp_path: Path) -> None:
    path = tmp_path / "clip.mp4"
    writer = VideoWriter(path, 30, (64, 48))
    writer.write(moving_bar(0, 64, 48))
    assert not path.exists() and writer.part.parent == tmp_path
    writer.abort()
    writer.abort()
    writer.close()  # after abort: nothing to do
    assert os.listdir(tmp_path) == []

    with pytest.raises(RuntimeError, match="boom"), VideoWriter(path, 30, (64, 48)) as writer:
        writer.write(moving_bar(0, 64, 48))
        raise RuntimeError("boom")
    assert os.listdir(tmp_path) == []


def test_a_video_without_frames_is_not_written(tmp_path: Path) -> None:
    with VideoWriter(tmp_path / "empty.mp4", 30, (64, 48)):
        pass
    assert os.listdir(tmp_path) == []


def test_close_twice_is_harmless_and_write_after_close_is_refused(tmp_path: Path) -> None:
    writer = VideoWriter(tmp_path / "a.mp4", 30, (64, 48))
    writer.write(moving_bar(0, 64, 48))
    writer.close()
    writer.close()
    assert "1 frames, closed" in repr(writer)
    with pytest.raises(Exception, match="already closed"):
        writer.write(moving_bar(0, 64, 48))


@pytest.mark.parametrize(("fps", "size"), [(0, (64, 48)), (float("nan"), (64, 48)), (30, (0, 48)), (30, (64,))])
def test_bad_rate_or_size_is_one_config_error(tmp_path: Path, fps: float, size: tuple) -> None:
    with pytest.raises(ConfigError, match="video"):
        VideoWriter(tmp_path / "a.mp4", fps, size)
    assert os.listdir(tmp_path) == []


def test_a_frame_of_the_wrong_shape_is_refused_by_name(tmp_path: Path) -> None:
    with VideoWriter(tmp_path / "a.mp4", 30, (64, 48)) as writer:
        with pytest.raises(ConfigError, match=r"\(48, 64, 3\) uint8.*\(48, 64\)"):
            writer.write(np.zeros((48, 64), np.uint8))
        writer.write(moving_bar(0, 64, 48))
    assert len(probe(tmp_path / "a.mp4")["frames"]) == 1


def test_a_failing_ffmpeg_leaves_no_file_and_says_why(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    fake = tmp_path / "ffmpeg"  # lists an H.264 encoder, then fails the encode as a full disk would
    fake.write_text("#!/bin/sh\n"
                    'case "$*" in *-encoders*) echo " V....D libx264   H.264"; exit 0;; esac\n'
                    "cat >/dev/null; echo 'No space left on device' >&2; exit 1\n")
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    monkeypatch.setenv("IMAGEIO_FFMPEG_EXE", str(fake))
    out = tmp_path / "out"
    out.mkdir()
    writer = VideoWriter(out / "a.mp4", 30, (64, 48))
    writer.write(moving_bar(0, 64, 48))
    with pytest.raises(OSError, match=r"a\.mp4.*No space left on device"):
        writer.close()
    assert os.listdir(out) == []


def test_demo_video_is_h264(tmp_path: Path) -> None:
    result = run_demo(tmp_path, seconds=0.2, size=(320, 180), progress=False)
    info = probe(result.video)
    assert info["codec"] == "h264" and info["pix_fmt"] == "yuv420p"
    assert len(info["frames"]) == result.frames
    assert abs(float(info["fps"]) - result.fps) < 1e-3
    assert not [p for p in os.listdir(tmp_path) if p.endswith(".part")]


class Nothing:
    """A detector that finds nothing (the video is what is under test)."""

    name, input, class_names = "nothing", "bgr", {PERSON: "person"}

    def detect(self, image: np.ndarray) -> Detections:
        return Detections(np.zeros((0, 4)), np.zeros(0), [])

    def close(self) -> None:
        pass


def test_detect_video_is_h264(tmp_path: Path, rollcam_camera) -> None:
    source = rollcam_camera("imx219", size="320x180", seed=1)
    run_detect(source, Nothing(), frames=4, out_dir=tmp_path)
    info = probe(tmp_path / VIDEO)
    assert info["codec"] == "h264" and info["pix_fmt"] == "yuv420p"
    assert info["size"] == (320, 180) and len(info["frames"]) == 4
    assert abs(float(info["fps"]) - float(source.info()["fps"])) < 1e-3
