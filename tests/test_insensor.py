"""The detector inside the camera: results on the device clock, over-budget skipping, every transport, the ledger."""

from __future__ import annotations

import itertools
import json
import math
import urllib.error
import urllib.request

import numpy as np
import pytest
from rollcam.common.errors import ConfigError, SourceError
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.imu import frame_end_ns
from rollcam.firmware.insensor import ACCELERATORS
from rollcam.firmware.insensor_stage import bin_mosaic
from rollcam.firmware.ledger import ledger
from rollcam.firmware.protocol import handle_line
from rollcam.firmware.spec import CameraSpec
from rollcam.host import open_camera
from rollcam.host.detectors.onchip import onnx_macs

pytest.importorskip("onnx")  # the in-sensor stage counts a network's operations from its graph

URI = "emu:letsroll?size=320x180&speed=fast&pedestrians=10&insensor=personnet-raw"
PERSONNET_RAW_MACS = 6_679_680
"""Multiply-accumulates of one run of the shipped personnet-raw at its 320x180 input (its card's figure)."""


def _frames(uri: str, n: int) -> list:
    with open_camera(f"{uri}&frames={n}") as cam:
        return list(cam)


def test_results_ride_on_the_next_frame_stamped_on_the_device_clock() -> None:
    frames = _frames(URI, 4)
    spec = CameraSpec.from_options("letsroll", {"size": "320x180", "insensor": "personnet-raw"})
    latency = math.ceil(PERSONNET_RAW_MACS * 1e9 / ACCELERATORS["imx500"].macs_per_s)
    assert frames[0].insensor == ()  # nothing was done before the first frame was read out
    for prev, f in itertools.pairwise(frames):
        (r,) = f.insensor
        assert r.seq == prev.sequence and r.macs == PERSONNET_RAW_MACS and r.input == "raw"
        assert (r.timestamp_ns, r.line_time_ns, r.exposure_ns, r.readout) == (
            prev.timestamp_ns, prev.line_time_ns, prev.exposure_ns, prev.readout.value)
        assert r.input_ns == frame_end_ns(spec, prev.timestamp_ns) and r.done_ns == r.input_ns + latency
        assert r.done_ns <= frame_end_ns(spec, f.timestamp_ns)  # done before the frame carrying it was read out
        assert len(r) and r.boxes.shape == (len(r), 4) and np.all(r.boxes[:, 2] <= 320)
        assert dict(r.tensors)["output0"].shape == (1, 5, 3600)  # the raw output tensor travels with it
        assert f.to_json()["insensor"][0]["seq"] == prev.sequence


def test_over_budget_frames_are_skipped_deterministically() -> None:
    # 0.0835 GMAC/s makes one run last 80 ms = 2.4 frame periods: frames 0, 3, 6 are inferred, the rest skipped.
    uri = f"{URI}&insensor_accel=0.0835"
    with open_camera(f"{uri}&frames=8") as cam:
        frames = list(cam)
        stats = cam.device.stats
    carried = {f.sequence: [r.seq for r in f.insensor] for f in frames}
    assert carried == {0: [], 1: [], 2: [], 3: [0], 4: [], 5: [], 6: [3], 7: []}
    assert (stats.insensor_runs, stats.insensor_skipped) == (3, 5)
    (r,) = frames[3].insensor
    assert r.latency_ns == math.ceil(PERSONNET_RAW_MACS * 1e9 / 0.0835e9)
    again = _frames(uri, 8)  # the device clock alone decides: the same stream gives the same results
    assert [[(r.seq, r.done_ns, r.boxes.tobytes()) for r in f.insensor] for f in again] == \
        [[(r.seq, r.done_ns, r.boxes.tobytes()) for r in f.insensor] for f in frames]


def test_metadata_only_mode_sends_no_image() -> None:
    frames = _frames(f"{URI}&insensor_output=meta", 3)
    for f in frames:
        assert f.data.size == 0 and f.meta["image"] is False and (f.width, f.height) == (320, 180)
    assert [r.seq for f in frames for r in f.insensor] == [0, 1]
    full = _frames(URI, 3)
    assert [r.boxes.tobytes() for f in full for r in f.insensor] == \
        [r.boxes.tobytes() for f in frames for r in f.insensor]  # same detections, image or not


def test_raw_input_is_the_mosaic_whatever_the_stream_format() -> None:
    bgr = _frames(URI, 2)[1].insensor[0]
    raw = _frames(f"{URI}&format=RGGB", 2)[1].insensor[0]
    assert raw.boxes.tobytes() == bgr.boxes.tobytes()  # the network saw the same samples


def test_bin_mosaic_keeps_each_colour_site() -> None:
    rgb = np.array([[10, 20], [30, 40]], np.uint16)  # an RGGB tile: R=10, G=20, G=30, B=40
    mosaic = np.tile(rgb, (8, 12))  # 16 x 24
    binned = bin_mosaic(mosaic, 2, "RGGB")
    assert binned.shape == (8, 12) and np.array_equal(binned, np.tile(rgb, (4, 6)))
    assert bin_mosaic(np.arange(16, dtype=np.uint16).reshape(4, 4), 2, "mono").tolist() == [[2, 4], [10, 12]]


def test_options_at_every_door() -> None:
    with pytest.raises(ConfigError, match="need an in-sensor network"):
        CameraSpec.from_options("letsroll", {"insensor_size": "320x320"})
    with pytest.raises(ConfigError, match="takes isp input"):
        CameraSpec.from_options("letsroll", {"insensor": "personnet", "insensor_input": "raw"})
    with pytest.raises(SourceError, match="insensor_accel"):
        open_camera(f"{URI}&insensor_accel=fastest")
    with pytest.raises(ConfigError, match="unknown detector 'nonet'"):
        CameraSpec.from_options("letsroll", {"insensor": "nonet"})
    cam = FirmwareCamera(CameraSpec.create("letsroll", size=(320, 180)))
    assert handle_line(cam, "OPT insensor personnet-raw") == "OK personnet-raw"
    assert handle_line(cam, "OPT? insensor_input") == "raw" and cam.spec.uses_physics
    assert handle_line(cam, "OPT insensor_output meta") == "OK meta"
    assert handle_line(cam, "OPT insensor none") == "OK none" and cam.spec.insensor is None


def test_ledger_matches_hand_computation() -> None:
    spec = CameraSpec.from_options("imx219", {"size": "640x480", "format": "RG10", "insensor": "personnet-raw",
                                              "insensor_output": "meta"})
    doc = ledger(spec, detections=3, tensor_bytes=1000, macs=10**6).to_json()
    fps = spec.settings.timing.fps
    raw = 480 * (640 * 10 // 8 + 6) + 8  # RAW10: 4 px in 5 bytes; 6 bytes of packet per line; FS + FE
    isp = 640 * 480 * 2 + 480 * 6 + 8  # a raw stream's ISP picture counted as YUYV
    meta = 64 + 3 * 24 + 6 + 8
    rows = doc["rows"]
    assert [rows[k]["bytes_per_frame"] for k in ("raw", "isp", "meta", "tensor", "sent")] == \
        [raw, isp, meta, 64 + 1000 + 14, meta]
    assert rows["raw"]["utilisation"] == round(raw * 8 * fps / (2 * 912e6), 6)
    e = doc["energy_uj_per_frame"]
    assert e["insensor_accel"] == round(10**6 * 2 / 4.97 / 1e6, 4)  # 4.97 TOPS/W, two ops a MAC
    assert e["insensor"] == round(10**6 * 2 / 4.97 / 1e6 + meta * 8 * 5.0 / 1e6, 4)
    host = raw * 8 * 5.0 + 8 * (2 * raw + 2 * 640 * 480 * 2) * 1300 / 64 + 10**6 * 4.6
    assert e["host"] == round(host / 1e6, 4)
    assert ledger(CameraSpec.create("ar0234")).to_json()["rows"]["raw"]["utilisation"] is None  # no link given


def test_op_count_of_the_shipped_model() -> None:
    from rollcam.host.detectors.personnet_raw import card

    assert card()["figures"]["macs"] == PERSONNET_RAW_MACS
    from rollcam.host.detectors.packaged import packaged_model

    path = str(packaged_model("models/personnet_raw", "personnet-raw", "tools/train_personnet_raw.sh"))
    assert onnx_macs(path, 320, 180) == PERSONNET_RAW_MACS
    assert onnx_macs(path, 640, 360) == pytest.approx(4 * PERSONNET_RAW_MACS, rel=0.02)  # convolutional: by area


def test_op_count_by_hand(tmp_path) -> None:
    import onnx
    from onnx import TensorProto, helper

    w = helper.make_tensor("w", TensorProto.FLOAT, [8, 3, 3, 3], np.zeros(8 * 27, np.float32).tolist())
    g = helper.make_tensor("g", TensorProto.FLOAT, [8, 5], np.zeros(40, np.float32).tolist())
    graph = helper.make_graph(
        [helper.make_node("Conv", ["x", "w"], ["c"], pads=[1, 1, 1, 1], strides=[2, 2], group=1),
         helper.make_node("GlobalAveragePool", ["c"], ["p"]), helper.make_node("Flatten", ["p"], ["f"]),
         helper.make_node("Gemm", ["f", "g"], ["y"])], "t",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 3, "h", "w"])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 5])], [w, g])
    path = tmp_path / "t.onnx"
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)]), path)
    # stride 2 on 32 x 16: 16 x 8 outputs of 8 channels, 3 x 3 x 3 MACs each; then a 8 -> 5 Gemm
    assert onnx_macs(str(path), 32, 16) == 16 * 8 * 8 * 27 + 8 * 5


def test_serial_insensor_and_ledger_queries() -> None:
    clock = [0]
    cam = FirmwareCamera(CameraSpec.from_options("letsroll", {"size": "320x180", "pedestrians": "10",
                                                              "insensor": "personnet-raw"}), clock=lambda: clock[0])
    assert handle_line(cam, "INSENSOR? 0") == "n=0 next=0"
    cam.stream_on()
    made = [cam.next_frame() for _ in range(3)]
    r0 = made[1].insensor[0]
    clock[0] = r0.done_ns - 1
    assert handle_line(cam, "INSENSOR? 0") == "n=0 next=0"  # not done yet on the device clock
    clock[0] = made[2].insensor[0].done_ns
    head, _, body = handle_line(cam, "INSENSOR? 0").partition(" ")
    assert head == "n=2" and body.startswith("next=2 ")
    first = body.split(" ", 1)[1].split(";")[0].split(",")
    assert [int(v) for v in first[:5]] == [0, r0.timestamp_ns, r0.input_ns, r0.done_ns, len(r0)]
    assert [float(v) for v in first[5:9]] == pytest.approx(r0.boxes[0].tolist(), abs=0.051)
    assert handle_line(cam, "INSENSOR? 2") == "n=0 next=2"
    reply = handle_line(cam, "LEDGER?")
    assert reply.startswith(f"raw={180 * (320 + 6) + 8} ") and "insensor_uj=" in reply
    assert handle_line(cam, "STATS?").endswith("insensor_runs=3 insensor_skipped=0 insensor_injected=0 "
                                               "insensor_injections_missed=0 loader_failures=0 frontend_timeouts=0 "
                                               "register_resets=0")


def test_http_jsonl_part_headers_and_metadata_only() -> None:
    from rollcam.emu.http.mjpeg import MjpegServer

    spec = CameraSpec.from_options("letsroll", {"size": "320x180", "pedestrians": "10", "insensor": "personnet-raw"})
    cam = FirmwareCamera(spec)
    with MjpegServer(cam) as srv:
        base = srv.url.rsplit("/", 1)[0]
        with urllib.request.urlopen(f"{base}/insensor.jsonl?results=3", timeout=60) as r:
            lines = [json.loads(x) for x in r.read().decode().splitlines()]
        with urllib.request.urlopen(srv.url, timeout=60) as r:
            heads = []
            while len(heads) < 2:
                line = r.readline().strip()
                if line != b"--rollcamframe":
                    continue
                head = dict(x.decode().split(": ", 1) for x in iter(lambda: r.readline().strip(), b""))
                r.read(int(head["Content-Length"]))
                heads.append(head)
        status = json.loads(urllib.request.urlopen(f"{base}/status.json", timeout=10).read())
        with open_camera(f"{srv.url}#frames=3") as src:  # the http:// source reads the results back into Frames
            got = list(src)
    assert lines[0]["insensor"]["insensor"] == "personnet-raw" and lines[0]["ledger"]["mode"] == "frame"
    seqs = [x["seq"] for x in lines[1:]]
    # In order, none twice; a frame the device skipped (a render late on a loaded machine) was never inferred.
    assert len(seqs) == 3 and seqs == sorted(set(seqs))
    assert seqs[-1] - seqs[0] - 2 <= cam.stats.skipped
    assert all(x["done_ns"] > x["input_ns"] and x["detections"] for x in lines[1:])
    carried = [json.loads(h["X-Insensor"]) for h in heads]
    for h, c in zip(heads, carried, strict=True):  # a part carries the result of the frame made before it
        assert all(x["seq"] < int(h["X-Sequence"]) for x in c) and len(c) <= 1 + cam.stats.skipped
    assert any(carried) or cam.stats.skipped  # none only when the frames before were skipped (a loaded machine)
    assert status["ledger"]["rows"]["raw"]["bytes_per_frame"] == 180 * 326 + 8
    assert all(r.seq < f.sequence and len(r.boxes) for f in got for r in f.insensor)

    cam = FirmwareCamera(CameraSpec.from_options("letsroll", {"size": "320x180", "pedestrians": "10",
                                                              "insensor": "personnet-raw", "insensor_output": "meta"}))
    with MjpegServer(cam) as srv:
        base = srv.url.rsplit("/", 1)[0]
        with pytest.raises(urllib.error.HTTPError, match="404"):
            urllib.request.urlopen(srv.url, timeout=10)
        with urllib.request.urlopen(f"{base}/insensor.jsonl?results=2", timeout=60) as r:
            lines = r.read().decode().splitlines()
    assert json.loads(lines[0])["ledger"]["mode"] == "meta" and len(lines) == 3



def test_emulate_names_the_results_endpoint_not_a_stream_in_metadata_only_mode() -> None:
    import argparse

    from rollcam.host.servers.emulate import start_http

    args = argparse.Namespace(http=("127.0.0.1", 0), detector=None, quality=80, faults=None)
    for output, want, absent in (("frame", "MJPEG stream:", "in-sensor:"), ("meta", "in-sensor:", "MJPEG")):
        cam = FirmwareCamera(CameraSpec.from_options("letsroll", {"size": "320x180", "insensor": "personnet-raw",
                                                                  "insensor_output": output}))
        running = start_http(args, cam, None)
        try:
            text = "\n".join(running.lines)
        finally:
            running.server.close()
        assert want in text and absent not in text, text

def test_detect_scores_the_results_against_their_own_frames(tmp_path) -> None:
    from rollcam.host.detectors import load_detector
    from rollcam.host.detectors.live import run_detect

    reader = load_detector("insensor")
    with open_camera(f"{URI}&frames=5") as cam:
        result = run_detect(cam, reader, out_dir=tmp_path, video=False)
    recs = [json.loads(x) for x in (tmp_path / "detections.jsonl").read_text().splitlines()]
    assert result.frames == 5 and [r["sequence"] for r in recs] == [0, 1, 2, 3]
    direct = _frames(URI, 5)
    assert recs[0]["detections"] == [{"box": [round(float(v), 2) for v in b], "score": round(float(s), 5),
                                      "cls": int(c)} for b, s, c in zip(direct[1].insensor[0].boxes,
                                                                        direct[1].insensor[0].scores,
                                                                        direct[1].insensor[0].classes, strict=True)]
    assert recs[0]["objects"] == [o.to_json() for o in direct[0].objects]  # scored against frame 0's truth
    assert result.truth.frames == 4
    with open_camera("emu:letsroll?size=320x180&frames=1") as cam, pytest.raises(SourceError, match="no in-sensor"):
        run_detect(cam, load_detector("insensor"))


def test_eval_scores_what_the_camera_sends_as_the_network_on_the_files(tmp_path) -> None:
    from rollcam.host.datasets import DatasetConfig, build_dataset
    from rollcam.host.evaluation.run import evaluate_dataset

    cfg = DatasetConfig(size=(320, 180), scenes=3, cameras=1, times=("noon",), speeds=("fast",), frames=3,
                        pedestrians=12, seed=5, raw_format="RGGB")
    build_dataset(cfg, tmp_path / "d")
    host = evaluate_dataset(tmp_path / "d", detector="personnet-raw?conf=0.01", split="test",
                            save_detections=tmp_path / "host.jsonl")
    chip = evaluate_dataset(tmp_path / "d", detector="insensor:personnet-raw?conf=0.01", split="test",
                            save_detections=tmp_path / "chip.jsonl")
    # The camera re-makes each image from its record and runs the network on its own mosaic: the same bytes.
    assert (tmp_path / "chip.jsonl").read_text() == (tmp_path / "host.jsonl").read_text()
    assert chip["results"] == host["results"] and host["results"]["fast"]["rs"]["images"] >= 1


def test_part_header_caps_the_detections_and_results_round_trip() -> None:
    from rollcam.emu.http.mjpeg import HEADER_DETECTIONS, Part
    from rollcam.sim.frame import Frame
    from rollcam.sim.insensor import InSensorResult
    from rollcam.sim.timing import Readout

    n = HEADER_DETECTIONS + 7
    boxes = np.arange(n * 4, dtype=np.float32).reshape(n, 4)
    r = InSensorResult(seq=4, boxes=boxes, scores=np.linspace(1, 0, n), classes=np.zeros(n), timestamp_ns=10,
                       line_time_ns=2, readout="top_to_bottom", exposure_ns=5, input_ns=20, done_ns=25,
                       tensors=(("out", np.ones((1, 5, 3), np.float32)),))
    frame = Frame(np.zeros((2, 2, 3), np.uint8), "BGR3", 5, 40, 2, Readout.TOP_TO_BOTTOM, 5, insensor=(r,))
    (head,) = json.loads(dict(Part.of(frame, b"").headers)["X-Insensor"])
    assert len(head["detections"]) == HEADER_DETECTIONS and head["truncated"] == 7 and head["seq"] == 4
    back = InSensorResult.from_json(r.to_json(tensors=True))
    assert back.to_json(tensors=True) == r.to_json(tensors=True) and back.latency_ns == 5


def test_bench_compares_the_two_pipelines_on_the_same_frames() -> None:
    from rollcam.benchmarks.insensor import run_insensor_bench
    from rollcam.benchmarks.studies import STUDIES, missed

    doc = run_insensor_bench(scenes=1, frames=2)
    host, chip = doc["pipelines"]["host"], doc["pipelines"]["insensor"]
    assert host["frames"] == chip["frames"] == 6 and not missed(STUDIES["insensor"].targets(doc))
    assert host["bytes_per_frame"] == 180 * (320 + 6) + 8  # the raw 8-bit frame, CSI-2 framed
    assert chip["bytes_per_frame"] == doc["ledger"]["rows"]["meta"]["bytes_per_frame"] < host["bytes_per_frame"]
    assert doc["ledger"]["mode"] == "meta" and chip["energy_uj"] < host["energy_uj"]


@pytest.mark.parametrize(("query", "want"), [("", False), ("?tensors=1", True), ("?tensors=yes", True),
                                             ("?tensors=no", False), ("?tensors=OFF", False), ("?tensors=0", False)])
def test_tensors_option_reads_the_one_boolean_vocabulary(query: str, want: bool) -> None:
    """``?tensors=no`` sent the tensors on main: the endpoint had its own list of false words, without "no"."""
    from types import SimpleNamespace

    from aiohttp.test_utils import make_mocked_request
    from rollcam.emu.http.insensor import InSensorStreams

    cam = SimpleNamespace(spec=SimpleNamespace(insensor="personnet-raw"), clock_ns=lambda: 0,
                          insensor=SimpleNamespace(recent=lambda now, since=0: []))
    streams = InSensorStreams(cam, slots=None)
    assert streams.open(make_mocked_request("GET", f"/insensor.jsonl{query}"))["tensors"] is want


def test_a_bad_tensors_value_is_a_400_naming_it() -> None:
    from types import SimpleNamespace

    from aiohttp import web
    from aiohttp.test_utils import make_mocked_request
    from rollcam.emu.http.insensor import InSensorStreams

    cam = SimpleNamespace(spec=SimpleNamespace(insensor="personnet-raw"), clock_ns=lambda: 0,
                          insensor=SimpleNamespace(recent=lambda now, since=0: []))
    with pytest.raises(web.HTTPBadRequest) as bad:
        InSensorStreams(cam, slots=None).open(make_mocked_request("GET", "/insensor.jsonl?tensors=maybe"))
    assert bad.value.text.startswith("tensors='maybe' is invalid (expected one of 1/on/true/yes")
