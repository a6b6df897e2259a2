"""The ``cv2.VideoCapture`` drop-in, driven by an unmodified OpenCV-style loop (previews: test_codecs.py)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from rollcam.common.errors import SourceError
from rollcam.host import VideoCapture


def opencv_script(capture_class, source, size=None):
    """A loop as written for OpenCV: open, optionally set the size, read until the end, release."""
    cap = capture_class(source)
    if size:
        cap.set(cv2.CAP_PROP_FRAME_WIDTH, size[0])
        cap.set(cv2.CAP_PROP_FRAME_HEIGHT, size[1])
    frames, stamps = [], []
    while cap.isOpened():
        ok, frame = cap.read()
        if not ok:
            break
        frames.append(frame)
        stamps.append(cap.get(cv2.CAP_PROP_POS_MSEC))
    cap.release()
    return frames, stamps


def test_emu_uri_runs_an_opencv_loop():
    frames, stamps = opencv_script(VideoCapture, "emu:imx219?frames=3&seed=1&pedestrians=4", size=(320, 180))
    assert len(frames) == 3 and all(f.shape == (180, 320, 3) and f.dtype == np.uint8 for f in frames)
    assert stamps[0] == 0.0 and stamps[1] > 0  # device timestamps in ms


def test_emu_properties_and_seek():
    cap = VideoCapture("emu:imx219?size=320x180&seed=1&pedestrians=4")
    assert cap.isOpened() and cap.getBackendName() == "rollcam:emu"
    assert (cap.get(cv2.CAP_PROP_FRAME_WIDTH), cap.get(cv2.CAP_PROP_FRAME_HEIGHT)) == (320, 180)
    assert cap.get(cv2.CAP_PROP_FRAME_COUNT) == -1 and cap.get(cv2.CAP_PROP_FPS) > 0
    assert cap.set(cv2.CAP_PROP_EXPOSURE, 2000) and cap.get(cv2.CAP_PROP_EXPOSURE) == pytest.approx(2000, rel=0.05)
    assert cap.set(cv2.CAP_PROP_POS_FRAMES, 5)
    ok, _img = cap.read()
    assert ok and cap.frame.sequence == 5 and cap.frame.objects is not None
    assert cap.get(cv2.CAP_PROP_POS_FRAMES) == 6
    assert cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)
    assert cap.read()[1] is cap.frame.data
    assert not cap.set(cv2.CAP_PROP_ZOOM, 2)
    cap.release()
    cap.release()
    assert not cap.isOpened() and cap.read() == (False, None)


def test_paths_and_files_behave_like_opencv(tmp_path):
    path = str(tmp_path / "clip.avi")
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 10, (64, 48))
    for i in range(4):
        writer.write(np.full((48, 64, 3), 40 * i, np.uint8))
    writer.release()
    ours, _ = opencv_script(VideoCapture, path)
    theirs, _ = opencv_script(cv2.VideoCapture, path)
    assert len(ours) == len(theirs) == 4
    assert all(np.array_equal(a, b) for a, b in zip(ours, theirs, strict=True))
    via_uri, stamps = opencv_script(VideoCapture, f"file:{path}")
    assert len(via_uri) == 4 and stamps[1] == pytest.approx(100.0)


def test_unopenable_uri_reports_like_opencv():
    cap = VideoCapture("emu:no_such_sensor")
    assert not cap.isOpened() and isinstance(cap.error, SourceError)
    assert cap.read() == (False, None)


def test_http_mjpeg_through_the_drop_in(rollcam_camera, rollcam_mjpeg_server):
    cam = rollcam_camera("imx219", size="160x90", seed=1, pedestrians=2)
    sent = [cam.read(), cam.read()]
    server = rollcam_mjpeg_server(sent)
    frames, stamps = opencv_script(VideoCapture, server.url)
    assert len(frames) == 2 and stamps == [f.timestamp_ns / 1e6 for f in sent]


def test_http_stream_reports_size_and_fps_before_the_first_read_like_opencv(tmp_path):
    """The usual recording script (a VideoWriter sized from the capture before any read) on the emulator's
    MJPEG stream: rollcam's drop-in knows what cv2.VideoCapture knows at open, and more (the device rate)."""
    from rollcam.emu.http.mjpeg import MjpegServer
    from rollcam.firmware.camera import FirmwareCamera

    camera = FirmwareCamera("imx219", scene={"scene": "flat"}, size=(640, 480))
    with MjpegServer(camera) as server:
        real = cv2.VideoCapture(server.url)
        want = [real.get(p) for p in (cv2.CAP_PROP_FRAME_WIDTH, cv2.CAP_PROP_FRAME_HEIGHT)]
        real.release()
        assert want == [640, 480]
        with VideoCapture(server.url) as cap:
            w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
            fps = cap.get(cv2.CAP_PROP_FPS)
            assert [w, h] == want
            writer = cv2.VideoWriter(str(tmp_path / "out.avi"), cv2.VideoWriter_fourcc(*"MJPG"), fps, (w, h))
            assert writer.isOpened()
            got = []
            for _ in range(3):
                ok, img = cap.read()
                assert ok and img.shape == (h, w, 3)
                got.append((cap.frame.sequence, cap.frame.timestamp_ns))
                writer.write(img)
            writer.release()
            assert got == sorted(set(got))  # the frames read ahead at open come back first, in order
            assert cap.get(cv2.CAP_PROP_POS_FRAMES) == 3
        (s0, t0), (s2, t2) = got[0], got[-1]
        assert fps == pytest.approx(1e9 * (s2 - s0) / (t2 - t0), rel=1e-3)  # the device's rate, from the headers


def test_http_stream_without_timestamps_reports_ffmpegs_rate(rollcam_mjpeg_server):
    images = [np.full((48, 64, 3), v, np.uint8) for v in (10, 90, 170)]
    server = rollcam_mjpeg_server(images)
    real = cv2.VideoCapture(server.url)
    want = (real.get(cv2.CAP_PROP_FRAME_WIDTH), real.get(cv2.CAP_PROP_FRAME_HEIGHT), real.get(cv2.CAP_PROP_FPS))
    real.release()
    with VideoCapture(server.url) as cap:
        got = (cap.get(cv2.CAP_PROP_FRAME_WIDTH), cap.get(cv2.CAP_PROP_FRAME_HEIGHT), cap.get(cv2.CAP_PROP_FPS))
        assert got == want == (64, 48, 25)
        assert len([cap.read()[1] for _ in range(3)]) == 3 and not cap.read()[0]  # none lost to the probe
