"""The picamera2 calls that published picamera2 scripts use beyond capturing: logging, overlays, platform,
allocators, stream descriptions, colour spaces, the switch-mode captures and EXIF (docs/picamera2.md)."""

from __future__ import annotations

import io
import logging
import os
import time

import numpy as np
import pytest
from PIL import Image

SMALL = {"size": (320, 240)}


def test_logging_overlay_platform_and_module_names(rollcam_picamera2):
    picamera2 = rollcam_picamera2()
    from picamera2 import Picamera2, Platform, TimeoutError, get_platform, libcamera

    out = io.StringIO()
    Picamera2.set_logging(Picamera2.INFO, output=out, msg="%(levelname)s %(message)s")
    logging.getLogger("picamera2").info("hello")
    assert out.getvalue() == "INFO hello\n"
    Picamera2.set_logging()
    assert get_platform() is Platform.VC4 and Picamera2.platform is Platform.VC4
    assert libcamera.Transform is __import__("libcamera").Transform
    with pytest.raises(TimeoutError):  # what a capture with wait=<seconds> raises when it runs out
        picamera2.Job(lambda: __import__("time").sleep(1)).get_result(0.01)
    with Picamera2() as cam:
        cam.start_preview(picamera2.Preview.NULL)
        cam.set_overlay(np.zeros((10, 10, 4), np.uint8))
        cam.set_overlay(None)
        with pytest.raises(RuntimeError, match="4-channel"):
            cam.set_overlay(np.zeros((10, 10, 3), np.uint8))


def test_colour_space_fields(rollcam_picamera2):
    rollcam_picamera2()
    from libcamera import ColorSpace

    cs = ColorSpace(ColorSpace.Sycc())
    assert cs == ColorSpace.Sycc() and cs.ycbcrEncoding == ColorSpace.YcbcrEncoding.Rec601
    cs.ycbcrEncoding, cs.range = ColorSpace.YcbcrEncoding.Null, ColorSpace.Range.Full
    assert cs != ColorSpace.Sycc()
    assert ColorSpace.Rec709().range == ColorSpace.Range.Limited


def test_allocators_are_accepted(rollcam_picamera2):
    picamera2 = rollcam_picamera2()
    from picamera2.allocators import DmaAllocator, LibcameraAllocator, PersistentAllocator

    with picamera2.Picamera2(allocator=PersistentAllocator()) as cam:
        cam.configure(cam.create_preview_configuration(main=SMALL, use_case="small"))
        assert set(cam.allocator.allocated) == {"preview"}
        cam.allocator.deallocate("preview")
        cam.allocator = LibcameraAllocator(cam.camera)
        cam.configure("still")
        assert isinstance(DmaAllocator(), picamera2.allocators.Allocator)


def test_switch_mode_captures_and_stream_map(rollcam_picamera2, tmp_path):
    picamera2 = rollcam_picamera2()
    with picamera2.Picamera2() as cam:
        cam.start(cam.create_preview_configuration(main=SMALL, controls={"FrameRate": 30}))
        other = cam.create_still_configuration(main={"size": (640, 480)}, raw={})
        buffers, md = cam.switch_mode_and_capture_buffers(other, ["main", "raw"], delay=1)
        assert buffers[0].shape == (640 * 480 * 3,) and buffers[1].ndim == 1 and "SensorTimestamp" in md
        assert cam.camera_configuration()["main"]["size"] == (320, 240)  # switched back
        image = cam.switch_mode_and_capture_image(other)
        assert isinstance(image, Image.Image) and image.size == (640, 480)
        assert cam.stream_map["main"].configuration.size == (320, 240)
        request = cam.switch_mode_capture_request_and_stop(other)
        assert not cam.started and request.make_array("main").shape == (480, 640, 3)
        assert request.stream_map["main"].configuration.size == (640, 480)
        request.release()
        name = str(tmp_path / "still{:d}.jpg")
        cam.start_and_capture_files(name, initial_delay=0, preview_mode=cam.create_preview_configuration(SMALL),
                                    capture_mode=other, num_files=2, delay=0.1)
        assert not cam.started
        assert [Image.open(name.format(i)).size for i in range(2)] == [(640, 480)] * 2


def test_capture_file_writes_exif_data(rollcam_picamera2):
    piexif = pytest.importorskip("piexif")
    picamera2 = rollcam_picamera2()
    with picamera2.Picamera2() as cam:
        cam.start(cam.create_preview_configuration(main=SMALL))
        mem = io.BytesIO()
        cam.capture_file(mem, format="jpeg", exif_data={"0th": {piexif.ImageIFD.Model: "Rolling"}})
    image = Image.open(io.BytesIO(mem.getvalue()))
    assert image.size == (320, 240)
    assert piexif.load(image.info["exif"])["0th"][piexif.ImageIFD.Model] == b"Rolling"


def test_capture_file_writes_png_through_the_one_image_encoder(rollcam_picamera2, tmp_path):
    picamera2 = rollcam_picamera2()
    with picamera2.Picamera2() as cam:
        cam.start(cam.create_preview_configuration(main=SMALL))
        cam.capture_file(str(tmp_path / "still.png"))
    assert (tmp_path / "still.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert Image.open(tmp_path / "still.png").size == (320, 240)


def test_dng_files_develop_in_libraw(rollcam_picamera2, tmp_path):
    rawpy = pytest.importorskip("rawpy")
    pytest.importorskip("pidng")
    picamera2 = rollcam_picamera2("emu:imx219?scene=flat&level=0.4")
    with picamera2.Picamera2() as cam:
        cam.start(cam.create_preview_configuration(main=SMALL, raw={"size": (640, 480)}))
        with cam.captured_request() as request:
            raw = request.make_array("raw")
            request.save_dng(str(tmp_path / "a.dng"))
            metadata = request.get_metadata()
        mem = io.BytesIO()
        cam.capture_file(mem, name="raw")
        buffers, md = cam.capture_buffers(["raw"])
        cam.helpers.save_dng(buffers[0], md, cam.camera_config["raw"], str(tmp_path / "b.dng"))
    assert raw.shape == (480, 800)  # SRGGB10_CSI2P: 5 bytes per 4 samples
    samples = raw.astype(np.uint16).reshape(480, 160, 5)
    expected = (samples[..., :4] << 2) | ((samples[..., 4:5] >> (2 * np.arange(4))) & 3)
    for source in (str(tmp_path / "a.dng"), io.BytesIO(mem.getvalue()), str(tmp_path / "b.dng")):
        with rawpy.imread(source) as dng:
            assert dng.raw_image.shape == (480, 640) and dng.raw_pattern.tolist() == [[0, 1], [3, 2]]  # RGGB
            assert dng.white_level == 1023 and dng.black_level_per_channel == [64] * 4
            rgb = dng.postprocess(use_camera_wb=True, no_auto_bright=True)
            assert rgb.shape == (480, 640, 3) and 10 < rgb.mean() < 245
            if source == str(tmp_path / "a.dng"):
                assert np.array_equal(dng.raw_image, expected.reshape(480, 640))  # the samples, bit for bit
    assert metadata["SensorBlackLevels"] == (4096,) * 4


def _remote_run(request, scale=1):
    from picamera2 import RemoteMappedArray  # in the child: the stand-in the parent imported

    with RemoteMappedArray(request, "main") as m:
        mean = float(m.array[..., :3].mean())
    return os.getpid(), request.make_array("main").shape, request.get_metadata()["RollcamSequence"], mean * scale


def test_requests_go_to_other_processes(rollcam_picamera2, tmp_path):
    picamera2 = rollcam_picamera2()
    from picamera2 import Pool, Process

    with picamera2.Picamera2() as cam:
        cam.start(cam.create_preview_configuration(main=SMALL, buffer_count=6))
        with Pool(_remote_run, 2, cam) as pool:
            futures, seqs = [], []
            for _ in range(4):
                with cam.captured_request() as request:
                    futures.append(pool.send(request, scale=2))
                    seqs.append(request.get_metadata()["RollcamSequence"])
        results = [f.result(30) for f in futures]
        assert len({r[0] for r in results}) == 2  # both processes got requests
        assert os.getpid() not in {r[0] for r in results}
        assert [r[2] for r in results] == seqs and all(tuple(r[1]) == (240, 320, 4) and r[3] > 0 for r in results)
        process = Process(lambda request: request.save(str(tmp_path / "child.png")) or "saved", cam)
        with cam.captured_request() as request:
            future = process.send(request)
        assert future.result(30) == "saved" and Image.open(tmp_path / "child.png").size == (320, 240)
        process.close()


def test_cancel_all_and_flush_cancels_jobs_in_flight(rollcam_picamera2):
    picamera2 = rollcam_picamera2()
    from picamera2 import CancelledError

    with picamera2.Picamera2() as cam:
        cam.start(cam.create_preview_configuration(main=SMALL, lores=SMALL, controls={"FrameRate": 1}))
        assert (cam.main_index, cam.lores_index, cam.raw_index) == (0, 1, 2)
        cam.capture_metadata()
        job = cam.capture_array(wait=False)  # the next frame is a second away
        cam.cancel_all_and_flush()
        with pytest.raises(CancelledError):
            job.get_result(1)
        started = time.monotonic()
        cam.stop()
        assert time.monotonic() - started < 1


def test_autofocus_states_of_the_camera_module_3(rollcam_picamera2):
    picamera2 = rollcam_picamera2("imx708")
    from libcamera import controls

    with picamera2.Picamera2() as cam:
        cam.start(cam.create_preview_configuration(main=SMALL, controls={"FrameRate": 30}))
        assert cam.capture_metadata()["AfState"] == controls.AfStateEnum.Idle
        cam.set_controls({"AfMode": controls.AfModeEnum.Continuous})
        cam.drop_frames(3)
        assert cam.capture_metadata()["AfState"] == controls.AfStateEnum.Focused
        cam.set_controls({"AfPause": controls.AfPauseEnum.Deferred})
        cam.drop_frames(3)
        assert cam.capture_metadata()["AfPauseState"] == controls.AfPauseStateEnum.Paused
        cam.set_controls({"AfMode": controls.AfModeEnum.Manual, "LensPosition": 3.0})
        cam.drop_frames(3)
        md = cam.capture_metadata()
        assert md["AfState"] == controls.AfStateEnum.Idle and md["LensPosition"] == 3.0
        assert cam.autofocus_cycle(wait=10) is True
        assert cam.capture_metadata()["AfState"] == controls.AfStateEnum.Focused


def test_configure_fills_in_the_callers_dict_and_its_controls(rollcam_picamera2):
    picamera2 = rollcam_picamera2()
    from libcamera import ColorSpace

    with picamera2.Picamera2() as cam:
        config = cam.create_video_configuration(main={**SMALL, "format": "RGB888"}, lores={"size": (160, 120)},
                                                raw={}, controls={"ExposureTime": 10000, "FrameRate": 25})
        cam.configure(config)
        assert config["main"]["stride"] == 320 * 3 and config["raw"]["stride"] > 0  # as picamera2 does
        assert cam.controls.ExposureTime == 10000 and cam.controls.FrameRate == pytest.approx(25)
        streams = cam.libcamera_config
        main = streams.at(cam.main_index).color_space
        assert (main.ycbcrEncoding, main.range) == (ColorSpace.YcbcrEncoding.Null, ColorSpace.Range.Full)
        assert streams.at(cam.lores_index).color_space == config["colour_space"]
        assert streams.at(cam.raw_index).color_space == ColorSpace.Raw()
        cam.encode_stream_name = "lores"
        assert cam.encode_stream_name == "lores"
        assert cam.create_preview_configuration(raw=None)["raw"] is None  # no raw stream, as asked
        assert cam.create_preview_configuration()["raw"] is not None


def test_tuning_files_are_described_and_accepted(rollcam_picamera2):
    picamera2 = rollcam_picamera2()
    from picamera2 import Picamera2

    tuning = Picamera2.load_tuning_file("imx477.json")
    contrast = Picamera2.find_tuning_algo(tuning, "rpi.contrast")
    curve = contrast["gamma_curve"]
    assert curve[:2] == [0, 0] and curve[-2:] == [65535, 65535] and curve[33] > curve[32]  # sRGB lifts mid-tones
    Picamera2.find_tuning_algo(tuning, "rpi.agc")["exposure_modes"]["normal"] = {"shutter": [100], "gain": [1.0]}
    fresh = Picamera2.find_tuning_algo(Picamera2.load_tuning_file("imx477.json"), "rpi.agc")
    assert fresh["exposure_modes"]["normal"]["shutter"] != [100]  # each load is a copy
    with picamera2.Picamera2(tuning=tuning) as cam:
        cam.configure("preview")
