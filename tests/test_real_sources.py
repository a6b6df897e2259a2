"""``http://``, ``opencv:``, ``v4l2:`` and ``oak:`` sources: real libraries where they run here, mocks elsewhere."""

from __future__ import annotations

import io
import sys

import cv2
import numpy as np
import pytest
from rollcam.common.errors import DeviceNotFoundError, MissingDependencyError, ProtocolError, SourceError
from rollcam.host import open_camera
from rollcam.host.sources import SourceURI
from rollcam.host.sources.http import HttpMjpegSource, MjpegParser, boundary_of

SMALL = {"size": "320x180", "seed": 2, "pedestrians": 6}


@pytest.fixture
def emu_frames(rollcam_camera):
    cam = rollcam_camera("imx219", **SMALL)
    return [cam.read() for _ in range(3)]


def test_http_mjpeg_carries_device_timing(emu_frames, rollcam_mjpeg_server):
    server = rollcam_mjpeg_server(emu_frames)
    with open_camera(server.url) as src:
        got = list(src)
    assert [f.sequence for f in got] == [f.sequence for f in emu_frames]
    for mine, sent in zip(got, emu_frames, strict=True):
        assert (mine.timestamp_ns, mine.exposure_ns, mine.line_time_ns) == (
            sent.timestamp_ns, sent.exposure_ns, sent.line_time_ns)
        assert mine.shutter == "rolling" and mine.format == "BGR3" and mine.data.shape == sent.data.shape
        assert mine.row_times_ns[1] - mine.row_times_ns[0] == sent.line_time_ns
        assert np.abs(mine.data.astype(int) - sent.data).mean() < 6  # JPEG round trip


def test_http_header_line_time_keeps_the_sensors_exact_rows(emu_frames, rollcam_mjpeg_server):
    # imx219's readout spread over 180 rows lasts 113,421.05 ns a line: X-Line-Time-Ns says 113421, so rows
    # multiplied out from the header drift from the sensor's true ones (9 ns at the bottom row here).
    server = rollcam_mjpeg_server(emu_frames)
    with open_camera(server.url + "#sensor=imx219") as src:
        got = list(src)
    for mine, sent in zip(got, emu_frames, strict=True):
        assert mine.line_time_ns == sent.line_time_ns
        assert np.array_equal(mine.row_times_ns, sent.row_times_ns)  # exact, to the ns, bottom rows included
    line = emu_frames[0].line_time_ns
    with open_camera(server.url) as src:  # no sensor: the header's whole-ns line time is all there is
        rows = src.read().row_times_ns
    assert np.array_equal(rows - rows[0], np.arange(180) * line)
    for headers, _ in server.parts:
        headers["X-Line-Time-Ns"] = "20000"
    with open_camera(server.url + "#sensor=imx219") as src:  # a line time that is not the sensor's wins
        f = src.read()
    assert f.line_time_ns == 20000 and np.array_equal(f.row_times_ns - f.row_times_ns[0], np.arange(180) * 20000)


@pytest.mark.parametrize(("header", "value", "match"), [
    ("X-Shutter", "sideways", "x-shutter='sideways'"),
    ("X-Readout", "diagonal", "x-readout='diagonal'"),
    ("X-Line-Time-Ns", "-5", "x-line-time-ns='-5'"),
    ("X-Line-Time-Ns", "0", "X-Shutter: rolling with X-Line-Time-Ns: 0"),
])
def test_http_bad_timing_headers_name_the_header(emu_frames, rollcam_mjpeg_server, header, value, match):
    server = rollcam_mjpeg_server(emu_frames[:1])
    server.parts[0][0][header] = value
    with open_camera(server.url) as src, pytest.raises(ProtocolError, match=match):
        src.read()


def test_http_global_shutter_header(emu_frames, rollcam_mjpeg_server):
    server = rollcam_mjpeg_server(emu_frames[:1])
    server.parts[0][0].update({"X-Shutter": "Global", "X-Line-Time-Ns": "0"})
    with open_camera(server.url + "#sensor=imx219") as src:
        f = src.read()
    assert f.shutter == "global" and f.line_time_ns == 0
    assert (f.row_times_ns == emu_frames[0].timestamp_ns + emu_frames[0].exposure_ns // 2).all()


def test_http_without_headers_uses_host_clock_and_named_sensor(emu_frames, rollcam_mjpeg_server):
    server = rollcam_mjpeg_server(emu_frames, timing_headers=False, content_length=False)
    ticks = iter(range(1000, 10**6, 1000))
    uri = server.url + "#sensor=imx219&frames=2"
    from rollcam.host.sources import parse_uri

    with HttpMjpegSource(parse_uri(uri), clock=lambda: next(ticks)) as src:
        got = list(src)
    assert [(f.sequence, f.timestamp_ns) for f in got] == [(0, 1000), (1, 2000)]
    assert got[0].shutter == "rolling" and got[0].line_time_ns > 0  # imx219's readout spread over 180 lines


def test_opencv_reads_the_same_mjpeg_stream(emu_frames, rollcam_mjpeg_server):
    server = rollcam_mjpeg_server(emu_frames)
    cap = cv2.VideoCapture(server.url)
    if not cap.isOpened():
        pytest.skip("this OpenCV build cannot read HTTP streams (no FFmpeg network support)")
    n = 0
    while True:
        ok, img = cap.read()
        if not ok:
            break
        assert img.shape == emu_frames[0].data.shape
        n += 1
    cap.release()
    assert n == len(emu_frames)


def test_mjpeg_parser_edge_cases():
    import io

    assert boundary_of('multipart/x-mixed-replace; boundary="--abc"') == b"--abc"
    with pytest.raises(ProtocolError, match="multipart"):
        boundary_of("image/jpeg")
    stream = io.BytesIO(b"--abc\r\nContent-Length: 3\r\n\r\nxyz\r\n----abc\r\n\r\nrest\r\n--abc--\r\n")
    parser = MjpegParser(stream, b"--abc")
    assert parser.next_part() == ({"content-length": "3"}, b"xyz")
    assert parser.next_part() == ({}, b"rest")
    assert parser.next_part() is None
    bad = MjpegParser(io.BytesIO(b"--abc\r\nno colon here\r\n\r\n"), b"abc")
    with pytest.raises(ProtocolError, match="malformed"):
        bad.next_part()


def test_http_errors_are_clear():
    with pytest.raises(DeviceNotFoundError, match="cannot connect"):
        open_camera("http://127.0.0.1:9/stream.mjpg#timeout=1")
    with pytest.raises(SourceError, match="unknown option"):
        open_camera("http://127.0.0.1:9/x#bogus=1")


def test_opencv_file_source_and_vectors(tmp_path, emu_frames):
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25, (320, 180))
    for f in emu_frames:
        writer.write(f.data)
    writer.release()
    with open_camera(f"opencv:{path}?sensor=imx219") as src:
        got = list(src)
        info = src.info()
    assert [f.sequence for f in got] == [0, 1, 2]
    assert [f.timestamp_ns for f in got] == [0, 40_000_000, 80_000_000]
    assert got[0].line_time_ns > 0 and info["sensor"] == "imx219"
    with open_camera(f"opencv:{path}") as src:
        assert src.read().shutter == "unknown"


def test_missing_cameras_say_what_to_plug_in():
    with pytest.raises(DeviceNotFoundError, match="no device '/dev/video99'"):
        open_camera("v4l2:/dev/video99")
    with pytest.raises(DeviceNotFoundError, match="no camera at that index"):
        open_camera("opencv:63")
    with pytest.raises(SourceError, match="sensor='nope'"):
        open_camera("opencv:63?sensor=nope")


def test_oak_source_on_the_mock(mock_depthai):
    with open_camera("oak:?size=320x180&frames=3") as src:
        frames = list(src)
        assert src.info()["sensor"] == "imx378"
    assert [f.sequence for f in frames] == [0, 1, 2]
    assert frames[0].shutter == "rolling" and frames[0].line_time_ns > 0 and frames[0].data.shape == (180, 320, 3)
    assert frames[1].timestamp_ns > frames[0].timestamp_ns
    with open_camera("oak:14442C10D13EABCE00?size=320x180&exposure_us=2000&gain=2") as src:
        f = src.read()
        assert f.exposure_ns == pytest.approx(2_000_000, rel=0.05) and f.meta["iso"] == 200
        src.set_control("exposure_us", 4000)
        assert src.read().exposure_ns == pytest.approx(4_000_000, rel=0.05)
    with pytest.raises(DeviceNotFoundError, match="no OAK with id 'XYZ'"):
        open_camera("oak:XYZ")
    mock_depthai.devices.clear()
    with pytest.raises(DeviceNotFoundError, match="no OAK device found; plug one in"):
        open_camera("oak:")


def test_oak_frames_are_stamped_at_start_of_exposure(mock_depthai):
    """depthai stamps an ImgFrame at the end of exposure; the Frame must carry the start, as emu: frames do."""
    with open_camera("oak:?size=320x180&frames=3&exposure_us=8000") as src:
        got = list(src)
    dev = mock_depthai.devices[0]
    with open_camera(f"emu:imx378?scene={dev.scene}&seed={dev.seed}&size=320x180&exposure_us=8000&gain=1.0"
                     "&frames=3") as src:
        sent = list(src)
    assert [f.exposure_ns for f in got] == [f.exposure_ns // 1000 * 1000 for f in sent]  # depthai keeps us
    assert got[0].exposure_ns == pytest.approx(8_000_000, rel=0.05)
    assert [f.timestamp_ns for f in got] == [f.timestamp_ns // 1000 * 1000 for f in sent]
    assert got[0].row_times_ns[0] - got[0].timestamp_ns == got[0].exposure_ns // 2  # first row: mid-exposure


def test_oak_options_are_checked_before_the_device_opens(mock_depthai):
    for bad in ("gain=abc", "exposure_us=abc", "exposure_us=0", "gain=-1", "exposure_us=0.2", "gain=0.001"):
        with pytest.raises(SourceError, match=bad.split("=")[0]):
            open_camera(f"oak:?size=320x180&{bad}")
        assert not mock_depthai.devices[0].opened, bad
    with open_camera("oak:?size=320x180") as src:  # the device is still free
        assert src.read() is not None


def test_oak_set_control_keeps_uri_exposure_and_gain(mock_depthai):
    with open_camera("oak:?size=320x180&exposure_us=2000&gain=3") as src:
        src.set_control("exposure_us", 4000)
        assert src.read().meta["iso"] == 300
        src.set_control("gain", 2)
        f = src.read()
        assert f.exposure_ns == pytest.approx(4_000_000, rel=0.05) and f.meta["iso"] == 200
        with pytest.raises(SourceError, match="exposure_us=0"):
            src.set_control("exposure_us", 0)
    controls = [(c.exposure_us, c.iso) for c in mock_depthai.devices[0].controls]
    assert controls == [(2000, 300), (4000, 300), (4000, 200)]


def test_oak_with_real_depthai_and_no_device():
    dai = pytest.importorskip("depthai")
    if dai.Device.getAllAvailableDevices():
        pytest.skip("an OAK is attached")
    with pytest.raises(DeviceNotFoundError, match="no OAK device found"):
        open_camera("oak:")


def test_oak_without_depthai_names_the_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "depthai", None)
    broken = r"an install dependency of rollcam missing from this broken install \(pip install depthai\)"
    with pytest.raises(MissingDependencyError, match=r"the oak: source needs depthai, " + broken):
        open_camera("oak:")


def test_typical_oak_capture_script_runs_on_the_mock(mock_depthai):
    mock_depthai.devices[0].frames = 4
    import depthai as dai  # the mock, installed by the fixture

    shapes, seqs = [], []
    with dai.Pipeline() as pipeline:
        cam = pipeline.create(dai.node.Camera).build(dai.CameraBoardSocket.CAM_A)
        queue = cam.requestOutput((640, 360), dai.ImgFrame.Type.BGR888i, fps=30).createOutputQueue()
        pipeline.start()
        while pipeline.isRunning():
            frame: dai.ImgFrame = queue.get()
            shapes.append(frame.getCvFrame().shape)
            seqs.append(frame.getSequenceNum())
    assert shapes == [(360, 640, 3)] * 4 and seqs == [0, 1, 2, 3]
    assert not mock_depthai.devices[0].opened


def test_source_uri_unchanged_for_http():
    from rollcam.host.sources import parse_uri

    assert parse_uri("http://h:1/a?b=c") == SourceURI("http://h:1/a?b=c", "http", "http://h:1/a?b=c", {})


def test_http_latest_mode_skips_to_the_newest_frame(emu_frames, rollcam_mjpeg_server):
    server = rollcam_mjpeg_server(emu_frames)
    with open_camera(server.url + "#latest=1") as src:
        src._latest._worker.join(30)  # the whole (finite) stream has arrived
        newest = src.read()
        assert src.read() is None
    assert newest.sequence == emu_frames[-1].sequence and newest.meta["dropped"] == len(emu_frames) - 1


def test_luxonis_style_example_on_the_mock(mock_depthai):
    """The shape of depthai 3's camera example: default socket, no frame type, isRunning loop, break."""
    import depthai as dai

    with dai.Pipeline() as pipeline:
        cam = pipeline.create(dai.node.Camera).build()
        video_queue = cam.requestOutput((640, 400)).createOutputQueue()
        full = cam.requestFullResolutionOutput()
        pipeline.start()
        n = 0
        while pipeline.isRunning():
            video_in = video_queue.get()
            assert isinstance(video_in, dai.ImgFrame)
            assert video_in.getCvFrame().shape == (400, 640, 3) and video_in.getTimestamp().total_seconds() >= 0
            n += 1
            if n == 2:
                break
    assert full.size == (1920, 1080)


def test_a_part_without_content_length_and_no_next_boundary_is_bounded(monkeypatch):
    """A server that never sends the next boundary cannot grow the reader's memory without bound."""
    import rollcam.host.sources.http as http_source

    monkeypatch.setattr(http_source, "MAX_PART_BYTES", 4096)
    endless = io.BytesIO(b"--abc\r\nContent-Type: image/jpeg\r\n\r\n" + (b"x" * 100 + b"\r\n") * 1000)
    with pytest.raises(ProtocolError, match="without Content-Length"):
        MjpegParser(endless, b"abc").next_part()
