"""Data injection on the emulated AI Camera, with the contract of Sony's modlib (``AiCamera(data_injection=True)
.inject(tensor)``): the tensor goes to the sensor through ``IMX500._IMX500__set_input_tensor(memfd)``, the driver
names the frame it will run on (``get_injection_cmp_frm``, 8 bits), and the output tensors come back on the
request whose ``CnnOutputTensorInfo.frameCount`` matches; a busy sensor answers errno 121 and modlib retries, as
it does a missed frame. The network's input on every frame is the IMX500 input tensor (``CnnInputTensor``).
"""

from __future__ import annotations

import contextlib
import itertools
import os
import threading
from types import SimpleNamespace

import numpy as np
import pytest
from helpers import metadata_with
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.input_tensor import parse_tensor_format
from rollcam.firmware.insensor import load_network
from rollcam.firmware.insensor_stage import tensor_input
from rollcam.host import open_camera
from test_input_tensor import model_of, modlib_isp

pytest.importorskip("onnx")  # the in-sensor stage counts a network's operations from its graph

SOURCE = "emu:imx500?pedestrians=12"
SSD = "/usr/share/imx500-models/imx500_network_ssd_mobilenetv2_fpnlite_320x320_pp.rpk"
FMT = parse_tensor_format("320x320,rgb,int8")


@pytest.fixture(scope="module")
def street():
    """A picture to inject: another street (seed 5) with people, as a user's test image."""
    with open_camera("emu:imx500?size=640x480&pedestrians=12&seed=5&frames=1") as cam:
        return next(iter(cam)).data


def set_input_tensor(imx500, tensor: np.ndarray) -> int:
    """What modlib's ``AiCamera.inject_input_tensor`` does: the bytes in a memfd, the fd to the driver."""
    fd = os.memfd_create("tensor_data", os.MFD_CLOEXEC)
    try:
        os.write(fd, tensor.tobytes())
        imx500._IMX500__set_input_tensor(fd)  # modlib calls it by this name
        return imx500.get_injection_cmp_frm()
    finally:
        os.close(fd)


def expected_boxes(tensor: np.ndarray) -> np.ndarray:
    """personnet run on the picture the tensor shows, its boxes in the 2028x1520 mode's pixels."""
    out = load_network("personnet").run(FMT.picture_bgr(tensor), 8)
    return np.asarray(out.boxes, np.float64).reshape(-1, 4) * [2028 / 320, 1520 / 320, 2028 / 320, 1520 / 320]


def test_each_frame_carries_its_input_tensor(rollcam_picamera2):
    """With injection on, the network's input is the IMX500 tensor the sensor made of that frame."""
    picamera2 = rollcam_picamera2(SOURCE)
    from picamera2.devices import IMX500

    imx500 = IMX500(SSD, tensor_injection=True)
    assert imx500.config["input_tensor"]["norm_val"] == [-2048] * 3
    with picamera2.Picamera2(imx500.camera_num) as picam2:
        picam2.start(picam2.create_preview_configuration(main={"size": (320, 240)}))
        metadata = metadata_with(picam2, "CnnInputTensor")
        spec = picam2.rollcam_device.spec
    assert spec.insensor.network == "personnet" and spec.insensor.tensor == FMT
    result = metadata["RollcamInsensor"][-1]
    frame, _ = FirmwareCamera(spec).imager.render_samples(spec, result["seq"], result["timestamp_ns"])
    tensor, picture, _ = tensor_input(spec.insensor, spec, frame)
    got = np.asarray(metadata["CnnInputTensor"], np.uint8)
    assert got.size == 3 * 320 * 320 and np.array_equal(got, FMT.planes(tensor).ravel())
    assert np.array_equal(imx500.input_tensor_image(got), picture)


def test_an_injected_tensor_runs_on_the_frame_it_names(rollcam_picamera2, street):
    picamera2 = rollcam_picamera2(SOURCE)
    from picamera2.devices import IMX500

    imx500 = IMX500(SSD, tensor_injection=True)
    tensor = FMT.prepare(street)
    with picamera2.Picamera2(imx500.camera_num) as picam2:
        picam2.start(picam2.create_preview_configuration(main={"size": (320, 240)},
                                                         controls={"CnnEnableInputTensor": True}))
        picam2.capture_metadata()
        cmp_frm = set_input_tensor(imx500, tensor)
        with pytest.raises(RuntimeError, match=r"Errno 121\] Remote I/O error") as busy:
            set_input_tensor(imx500, tensor)  # the first still waits for its frame
        assert busy.value.errno == 121
        for _ in range(20):
            metadata = picam2.capture_metadata()
            carried = metadata.get("RollcamInsensor") or []
            if any(r["injected"] for r in carried):
                break
        stats = picam2.rollcam_device.stats
    result = carried[-1]
    assert result["injected"] and result["seq"] % 256 == cmp_frm
    # As picamera2's injection demo reads the frame counter:
    assert imx500._IMX500__get_output_tensor_info(metadata["CnnOutputTensorInfo"])["frameCount"] == cmp_frm
    assert np.array_equal(np.asarray(metadata["CnnInputTensor"], np.uint8), FMT.planes(tensor).ravel())
    want = expected_boxes(tensor)
    got = np.array([d["box"] for d in result["detections"]], np.float64).reshape(-1, 4)
    assert len(got) == len(want) > 0
    assert np.allclose(np.sort(got, axis=0), np.sort(want, axis=0), atol=0.01)
    assert (stats.insensor_injected, stats.insensor_injections_missed) == (1, 0)


def test_injection_needs_it_turned_on(rollcam_picamera2):
    picamera2 = rollcam_picamera2(SOURCE)
    from picamera2.devices import IMX500

    imx500 = IMX500(SSD)
    with picamera2.Picamera2(imx500.camera_num) as picam2:
        picam2.start(picam2.create_preview_configuration(main={"size": (320, 240)}))
        with pytest.raises(RuntimeError, match="tensor_injection=True"):
            set_input_tensor(imx500, FMT.prepare(np.zeros((8, 8, 3), np.uint8)))


def test_a_busy_accelerator_misses_the_injection(street):
    """The comparison frame comes while the accelerator is still busy: it is not run, the miss is counted, and
    the next injection names the next frame."""
    fmt = parse_tensor_format("64x64,rgb,int8")
    with open_camera("emu:imx500?size=506x380&insensor=personnet&insensor_tensor=64x64,rgb,int8"
                     "&insensor_accel=0.001&frames=4") as cam:
        frames = iter(cam)
        first = next(frames)
        device = cam.device
        assert device.inject(fmt.prepare(street)) == first.sequence + 1
        second = next(frames)
        assert device.inject(fmt.prepare(street).tobytes()) == second.sequence + 1
        rest = list(frames)
        stats = device.stats
    assert (stats.insensor_runs, stats.insensor_skipped) == (1, 3)
    assert (stats.insensor_injected, stats.insensor_injections_missed) == (0, 2)
    assert not any(r.injected for f in [first, second, *rest] for r in f.insensor)


def test_injection_needs_an_input_tensor_of_the_right_size():
    from rollcam.common.errors import ConfigError, SourceError

    with open_camera("emu:imx500?size=506x380&insensor=personnet&frames=1") as cam, \
            pytest.raises(ConfigError, match="insensor_tensor=WxH"):
        cam.device.inject(b"\0" * 100)
    with open_camera("emu:imx500?size=506x380&insensor=personnet&insensor_tensor=64x64&frames=1") as cam, \
            pytest.raises(ValueError, match=r"100 samples is not 3x64x64 nor the padded 3x64x64"):
        cam.device.inject(b"\0" * 100)
    with pytest.raises(SourceError, match="insensor_tensor needs a network that takes a picture"):
        open_camera("emu:imx500?size=506x380&insensor=personnet-raw&insensor_tensor=64x64")
    with pytest.raises(SourceError, match=r"insensor_tensor.*unknown input tensor part 'fp16'"):
        open_camera("emu:imx500?size=506x380&insensor=personnet&insensor_tensor=64x64,fp16")


# ------------------------------------------------------------------------------------- modlib's own code
def modlib_camera(imx500):
    """modlib's ``AiCamera`` inject and request parsing, bound to the stand-in's IMX500 (its libcamera side is a
    capture thread below)."""
    modlib_isp()
    from modlib.devices.ai_camera.ai_camera import AiCamera
    from modlib.models.post_processors import pp_od_bscn

    cam = SimpleNamespace(imx500=imx500, _frames=[], _frameslock=threading.Lock(), data_injection=True,
                          enable_input_tensor=False, last_detections=None, roi=None,
                          model=SimpleNamespace(post_process=pp_od_bscn),
                          dps=SimpleNamespace(update=lambda: None, value=0.0), fps=SimpleNamespace(value=0.0))
    cam._frame_ready = threading.Condition(cam._frameslock)
    cam._parse_output_tensor_info = AiCamera._parse_output_tensor_info
    cam._get_output_tensor_shape = AiCamera._get_output_tensor_shape
    cam.inject_input_tensor = lambda data: AiCamera.inject_input_tensor(cam, data)
    cam.inject = lambda tensor, max_retries=100: AiCamera.inject(cam, tensor, max_retries)
    cam.parse = lambda metadata: AiCamera._parse_request(cam, SimpleNamespace(metadata=metadata, image=None))
    return cam


def test_modlibs_inject_gets_the_injected_frames_detections(rollcam_picamera2, street):
    isp = modlib_isp()
    from modlib.models import COLOR_FORMAT

    picamera2 = rollcam_picamera2(SOURCE)
    from picamera2.devices import IMX500

    imx500 = IMX500(SSD, tensor_injection=True)
    tensor, _ = isp.prepare_tensor_like_isp(street, model_of(FMT), COLOR_FORMAT.BGR)  # modlib makes the tensor
    assert np.array_equal(tensor, FMT.prepare(street))
    cam = modlib_camera(imx500)
    stop = threading.Event()
    with picamera2.Picamera2(imx500.camera_num) as picam2:
        picam2.start(picam2.create_preview_configuration(main={"size": (320, 240)}))

        def requests() -> None:  # libcamera's side of modlib's AiCamera: each request parsed as it arrives
            while not stop.is_set():
                cam.parse(picam2.capture_metadata())

        thread = threading.Thread(target=requests, daemon=True)
        thread.start()
        try:
            detections = cam.inject(tensor)
            again = cam.inject(tensor)  # a second injection, the first long consumed
        finally:
            stop.set()
            thread.join(timeout=60)
        stats = picam2.rollcam_device.stats
    want = expected_boxes(tensor)
    assert len(detections) == len(want) > 0 and len(again) == len(want)
    # modlib's detections: boxes normalised to the pixel array (x0, y0, x1, y1), best first.
    got = np.sort(np.asarray(detections.bbox, np.float64) * [4056, 3040, 4056, 3040], axis=0)
    assert np.allclose(got, np.sort(want * 2, axis=0), atol=0.05)
    assert stats.insensor_injected == 2


# ------------------------------------------------------------------------------ the AI Camera's failures
def capture_until_failure(picamera2, imx500) -> tuple[list[dict], RuntimeError, object]:
    """Capture from the AI Camera until it fails; the metadata captured, the error, and the camera's stats."""
    got: list[dict] = []
    with picamera2.Picamera2(imx500.camera_num) as picam2:
        picam2.start(picam2.create_preview_configuration(main={"size": (320, 240)}))
        with pytest.raises(RuntimeError) as failed:
            while len(got) < 400:  # the loop ends with the failure
                got.append(picam2.capture_metadata())
        stats = picam2.rollcam_device.stats
        with contextlib.suppress(Exception):  # the engine re-raises the failure on stop
            picam2.stop()
    return got, failed.value, stats


def test_the_firmware_loader_fails_after_the_time_given(rollcam_picamera2):
    picamera2 = rollcam_picamera2(f"{SOURCE}&faults=loaderfail=400")
    from picamera2.devices import IMX500

    got, error, stats = capture_until_failure(picamera2, IMX500(SSD))
    assert "failed to load loader firmware" in str(error)
    first = got[0]["RollcamDeviceTimestamp"]
    assert got and all(m["RollcamDeviceTimestamp"] - first < 400_000_000 for m in got)
    failed_seq = int(str(error).rsplit("frame ", 1)[1].rstrip(")'\""))
    period = got[0]["RollcamFrameDurationNs"]
    assert (failed_seq - got[0]["RollcamSequence"]) * period >= 400_000_000 - period  # at or after 400 ms
    assert stats.loader_failures == 1 and stats.frontend_timeouts == 0


def test_the_front_end_times_out_on_the_seeded_frame(rollcam_picamera2):
    from rollcam.common.faults import FaultPlan

    picamera2 = rollcam_picamera2(f"{SOURCE}&faults=fetimeout=10,seed=4")
    from picamera2.devices import IMX500

    got, error, stats = capture_until_failure(picamera2, IMX500(SSD))
    assert "Camera frontend has timed out!" in str(error)
    plan = FaultPlan.parse("fetimeout=10,seed=4")
    failed_seq = int(str(error).rsplit("frame ", 1)[1].rstrip(")'\""))
    assert plan.fires("fetimeout", failed_seq)
    assert not any(plan.fires("fetimeout", m["RollcamSequence"]) for m in got)
    assert stats.frontend_timeouts == 1 and stats.loader_failures == 0


def test_a_network_slower_than_the_frame_rate_skips_frames():
    """dnn_us=58800 (YOLO11n on the AI Camera, as Ultralytics measure it) at 30 fps: every other frame is
    inferred; the frames between carry no result (no output tensors), and the counts say so."""
    with open_camera("emu:imx500?size=506x380&insensor=personnet&insensor_tensor=320x320&frames=12"
                     "&faults=dnn_us=58800") as cam:
        frames = list(cam)
        stats = cam.device.stats
    period = frames[1].timestamp_ns - frames[0].timestamp_ns
    assert abs(period - 1e9 / 30) < 1e5
    inferred = sorted({r.seq for f in frames for r in f.insensor})
    assert inferred == [0, 2, 4, 6, 8]  # frame 10's result is done after frame 11's input
    assert all(r.latency_ns == 58_800_000 for f in frames for r in f.insensor)
    assert (stats.insensor_runs, stats.insensor_skipped) == (6, 6)
    assert [bool(f.insensor) for f in frames] == [False, False] + [True, False] * 5


def test_v4l2_and_serial_see_the_loader_failure_and_the_skips():
    """Through the user-space V4L2 device and pyserial's STATS? on the same camera: a 58.8 ms network at 30 fps
    infers every other frame; 300 ms in, the loader fails and DQBUF answers with it."""
    serial = pytest.importorskip("serial")
    from rollcam.emu.serial_pty import PtySerialServer
    from rollcam.emu.v4l2 import Device, EmuDriver
    from rollcam.firmware.spec import CameraSpec

    spec = CameraSpec.from_options("imx500", {"size": "506x380", "insensor": "personnet",
                                              "insensor_tensor": "64x64"})
    camera = FirmwareCamera(spec)
    driver = EmuDriver(camera, realtime=False, faults="dnn_us=58800,loaderfail=300")
    period = spec.settings.timing.frame_period_ns
    failing = -(-300_000_000 // period)  # the first frame starting 300 ms or more after frame 0
    with PtySerialServer(camera) as srv, serial.Serial(srv.path, timeout=5) as port, Device(driver) as d:
        seqs = []
        with pytest.raises(OSError, match=rf"failed to load loader firmware \(frame {failing}\)"):
            seqs.extend(b.sequence for b in d.stream(frames=failing + 5))
        assert seqs == list(range(failing))
        port.write(b"STATS?\n")
        stats = dict(kv.split("=") for kv in port.readline().decode().split())
    runs = (failing + 1) // 2
    assert stats["loader_failures"] == "1" and stats["frontend_timeouts"] == "0"
    assert (int(stats["insensor_runs"]), int(stats["insensor_skipped"])) == (runs, failing - runs)


def test_a_result_rides_on_the_next_frame_made_however_many_were_skipped():
    """A slow consumer makes the device skip frames; the result of the last frame made rides on the next one made,
    even 40 frames on (more than the 32 frames' runs the stage keeps)."""
    from rollcam.firmware.spec import CameraSpec
    from rollcam.firmware.stream import FramePlan

    spec = CameraSpec.from_options("imx500", {"size": "506x380", "insensor": "personnet",
                                              "insensor_tensor": "64x64"})
    cam = FirmwareCamera(spec)
    sched = cam.schedule(0)
    first = cam.render(FramePlan(0, sched))
    later = cam.render(FramePlan(40, sched))
    assert first.insensor == () and [r.seq for r in later.insensor] == [0]


def test_http_insensor_jsonl_shows_the_slow_networks_latency():
    """/insensor.jsonl under faults=dnn_us=58800: every result 58.8 ms after its input, and never two frames in a
    row inferred (the frame after an inferred one comes while the accelerator is busy)."""
    import json
    import urllib.request

    from rollcam.emu.http.mjpeg import MjpegServer
    from rollcam.firmware.spec import CameraSpec

    spec = CameraSpec.from_options("imx500", {"size": "506x380", "insensor": "personnet",
                                              "insensor_tensor": "64x64"})
    cam = FirmwareCamera(spec)
    with MjpegServer(cam, faults="dnn_us=58800") as srv:
        base = srv.url.rsplit("/", 1)[0]
        with urllib.request.urlopen(f"{base}/insensor.jsonl?results=4", timeout=120) as r:
            lines = [json.loads(x) for x in r.read().decode().splitlines()]
    assert lines[0]["insensor"]["insensor_tensor"] == "64x64,rgb,uint8"
    results = lines[1:]
    seqs = [x["seq"] for x in results]
    assert len(seqs) == 4 and all(b - a >= 2 for a, b in itertools.pairwise(seqs))
    assert all(x["done_ns"] - x["input_ns"] == 58_800_000 and x["input_size"] == [64, 64] for x in results)
    assert cam.stats.insensor_runs >= 4
