"""picamera2's encoders and outputs on the stand-in: the files ffprobe (Debian's ffmpeg, an independent
reader) finds in them, frame by frame, against the timestamps of the frames the camera made."""

from __future__ import annotations

import io
import json
import shutil
import subprocess
import time

import pytest
from helpers import wait_for

pytestmark = pytest.mark.skipif(shutil.which("ffprobe") is None, reason="needs ffprobe (apt: ffmpeg)")

SMALL = {"size": (320, 240)}


def probe_packets(path) -> list[dict]:
    """Every video packet of a file: pts_time and flags, as ffprobe reads them."""
    out = subprocess.run(["ffprobe", "-v", "error", "-select_streams", "v:0", "-show_entries",
                          "packet=pts_time,flags:stream=codec_name,width,height", "-of", "json", str(path)],
                         capture_output=True, text=True, check=True, timeout=60).stdout
    data = json.loads(out)
    return data["streams"][0], data["packets"]


def decoded_frames(path, fmt: str | None = None) -> int:
    """How many frames ffprobe decodes from a file."""
    args = ["-f", fmt] if fmt else []
    out = subprocess.run(["ffprobe", "-v", "error", *args, "-count_frames", "-select_streams", "v:0",
                          "-show_entries", "stream=nb_read_frames", "-of", "csv=p=0", str(path)],
                         capture_output=True, text=True, check=True, timeout=60).stdout
    return int(out.strip())


def record(picamera2, cam, encoder, output, seconds: float = 1.5, **kwargs) -> list[int]:
    """Record for a while; the SensorTimestamps of the frames the camera handed to the encoder."""
    stamps: list[int] = []
    cam.post_callback = lambda request: stamps.append(request.get_metadata()["SensorTimestamp"])
    cam.start_recording(encoder, output, **kwargs)
    time.sleep(seconds)
    cam.stop_recording()
    cam.post_callback = None
    return stamps


def test_h264_into_an_mp4_has_every_frame_at_its_device_time(rollcam_picamera2, tmp_path):
    picamera2 = rollcam_picamera2()
    from picamera2.encoders import H264Encoder
    from picamera2.outputs import FfmpegOutput

    with picamera2.Picamera2() as cam:
        cam.configure(cam.create_video_configuration(main=SMALL, controls={"FrameRate": 20}))
        stamps = record(picamera2, cam, H264Encoder(bitrate=2_000_000, iperiod=10),
                        FfmpegOutput(str(tmp_path / "v.mp4")))
    stream, packets = probe_packets(tmp_path / "v.mp4")
    assert (stream["codec_name"], stream["width"], stream["height"]) == ("h264", 320, 240)
    assert len(stamps) >= 5 and len(packets) == len(stamps) == decoded_frames(tmp_path / "v.mp4")
    expected = [(t - stamps[0]) / 1e9 for t in stamps]
    assert [float(p["pts_time"]) for p in packets] == pytest.approx(expected, abs=2e-6)
    assert "K" in packets[0]["flags"]  # it starts with a keyframe


def test_h264_elementary_stream_with_its_timestamp_file(rollcam_picamera2, tmp_path):
    picamera2 = rollcam_picamera2()
    from picamera2.encoders import H264Encoder, Quality

    with picamera2.Picamera2() as cam:
        cam.configure(cam.create_video_configuration(main=SMALL, controls={"FrameRate": 20}))
        stamps = record(picamera2, cam, H264Encoder(), str(tmp_path / "v.h264"), pts=str(tmp_path / "pts.txt"),
                        quality=Quality.HIGH)
    lines = (tmp_path / "pts.txt").read_text().splitlines()  # no header line, as picamera2's
    assert [float(x) for x in lines] == pytest.approx([(t - stamps[0]) / 1e6 for t in stamps], abs=1e-3)
    assert decoded_frames(tmp_path / "v.h264", "h264") == len(stamps)


def test_mjpeg_file_and_jpeg_frames_into_matroska(rollcam_picamera2, tmp_path):
    picamera2 = rollcam_picamera2()
    from picamera2.encoders import JpegEncoder, MJPEGEncoder
    from picamera2.outputs import FfmpegOutput

    with picamera2.Picamera2() as cam:
        cam.configure(cam.create_video_configuration(main={**SMALL, "format": "YUV420"},
                                                     controls={"FrameRate": 10}))
        stamps = record(picamera2, cam, MJPEGEncoder(), str(tmp_path / "v.mjpeg"), seconds=1)
        assert decoded_frames(tmp_path / "v.mjpeg", "mjpeg") == len(stamps) > 0
        stamps = record(picamera2, cam, JpegEncoder(q=60), FfmpegOutput(str(tmp_path / "v.mkv")), seconds=1)
    stream, packets = probe_packets(tmp_path / "v.mkv")
    assert stream["codec_name"] == "mjpeg" and len(packets) == len(stamps) > 0
    assert [float(p["pts_time"]) for p in packets] == pytest.approx([(t - stamps[0]) / 1e9 for t in stamps],
                                                                    abs=1e-3)  # Matroska keeps ms


def test_circular_output_writes_from_a_keyframe(rollcam_picamera2, tmp_path):
    picamera2 = rollcam_picamera2()
    from picamera2.encoders import H264Encoder
    from picamera2.outputs import CircularOutput

    with picamera2.Picamera2() as cam:
        cam.configure(cam.create_video_configuration(main=SMALL, controls={"FrameRate": 20}))
        output = CircularOutput(buffersize=8)
        cam.start_recording(H264Encoder(iperiod=5), output)
        time.sleep(1)
        output.fileoutput = str(tmp_path / "ring.h264")
        output.start()
        time.sleep(0.5)
        output.stop()
        cam.stop_recording()
    frames = decoded_frames(tmp_path / "ring.h264", "h264")
    assert frames >= 3  # the ring from its oldest keyframe on, then the frames that followed


def test_the_null_encoder_passes_raw_frames_and_start_and_record_video(rollcam_picamera2, tmp_path):
    picamera2 = rollcam_picamera2()
    from picamera2.encoders import Encoder
    from picamera2.outputs import FileOutput

    with picamera2.Picamera2() as cam:
        cam.configure(cam.create_video_configuration(main={**SMALL, "format": "YUV420"},
                                                     controls={"FrameRate": 10}))
        buffer = io.BytesIO()
        stamps = record(picamera2, cam, Encoder(), FileOutput(buffer), seconds=1)
        assert len(buffer.getvalue()) == len(stamps) * 320 * 240 * 3 // 2 > 0
        cam.start_and_record_video(str(tmp_path / "v.mp4"), duration=1)
        assert not cam.started
    stream, packets = probe_packets(tmp_path / "v.mp4")
    assert stream["codec_name"] == "h264" and len(packets) > 0


def test_circular_output2_into_a_pyav_output(rollcam_picamera2, tmp_path):
    picamera2 = rollcam_picamera2()
    from picamera2.encoders import H264Encoder
    from picamera2.outputs import CircularOutput2, PyavOutput

    with picamera2.Picamera2() as cam:
        cam.configure(cam.create_video_configuration(main=SMALL, controls={"FrameRate": 20}))
        ring = CircularOutput2(buffer_duration_ms=500)
        stamps = record(picamera2, cam, H264Encoder(iperiod=4), ring, seconds=0.1)  # nothing opened: dropped
        made: list[int] = []
        cam.post_callback = lambda request: made.append(request.get_metadata()["SensorTimestamp"])
        cam.start_recording(H264Encoder(iperiod=4), ring)
        wait_for(lambda: len(made) >= 12, what="12 frames into the ring (three keyframe periods)")
        ring.open_output(PyavOutput(str(tmp_path / "ring.mp4")))
        opened_at = len(made)
        wait_for(lambda: len(made) >= opened_at + 6, what="6 frames after the output opened")
        ring.close_output()
        cam.stop_recording()
        cam.post_callback = None
    stream, packets = probe_packets(tmp_path / "ring.mp4")
    assert stream["codec_name"] == "h264" and len(packets) >= 2 and stamps is not None
    assert float(packets[0]["pts_time"]) == 0 and "K" in packets[0]["flags"]  # from the ring's oldest keyframe
    times = [float(p["pts_time"]) for p in packets]
    assert times == sorted(times) and len(set(times)) == len(times)


def test_splittable_output_switches_at_a_keyframe(rollcam_picamera2, tmp_path):
    picamera2 = rollcam_picamera2()
    from picamera2.encoders import H264Encoder
    from picamera2.outputs import FileOutput, SplittableOutput

    with picamera2.Picamera2() as cam:
        cam.configure(cam.create_video_configuration(main=SMALL, controls={"FrameRate": 20}))
        splitter = SplittableOutput(output=FileOutput(str(tmp_path / "a.h264")))
        cam.start_recording(H264Encoder(iperiod=3), splitter)
        time.sleep(0.7)
        splitter.split_output(FileOutput(str(tmp_path / "b.h264")))
        time.sleep(0.7)
        cam.stop_recording()
    first, second = (decoded_frames(tmp_path / n, "h264") for n in ("a.h264", "b.h264"))
    assert first > 0 and second > 0  # b starts at a keyframe, so it decodes from its first frame


def test_an_output_attached_while_recording_starts_at_a_fresh_keyframe(rollcam_picamera2, tmp_path):
    picamera2 = rollcam_picamera2()
    from picamera2.encoders import H264Encoder
    from picamera2.outputs import FfmpegOutput

    with picamera2.Picamera2() as cam:
        cam.configure(cam.create_video_configuration(main=SMALL, controls={"FrameRate": 20}))
        encoder = H264Encoder(iperiod=1000)  # no keyframe of its own after the first
        cam.start_recording(encoder, None)
        cam.capture_metadata()
        output = FfmpegOutput(str(tmp_path / "late.mp4"))
        output.start()
        encoder.output = output
        time.sleep(0.5)
        cam.stop_recording()
    _, packets = probe_packets(tmp_path / "late.mp4")
    assert packets and "K" in packets[0]["flags"]
