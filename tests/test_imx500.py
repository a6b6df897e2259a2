"""The IMX500 (Raspberry Pi AI Camera) in the picamera2 stand-in: a script written as picamera2's object
detection example runs unchanged, and the boxes it parses from the output tensors are the in-sensor
stage's detections of the frame they came from, on the device clock.
"""

from __future__ import annotations

import ctypes
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import metadata_with
from rollcam.firmware.camera import FirmwareCamera
from rollcam.host import standin_env

pytest.importorskip("onnx")  # the in-sensor stage counts a network's operations from its graph

EXAMPLES = Path(__file__).parent / "picamera2_examples"
SOURCE = "emu:imx500?pedestrians=12"


def run_detect(*args: str, source: str = SOURCE) -> dict:
    done = subprocess.run([sys.executable, str(EXAMPLES / "imx500_detect.py"), *args], env=standin_env([source]),
                          cwd=EXAMPLES, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def main_box(box: list[float], raw: tuple[int, int], main: tuple[int, int]) -> list[float]:
    """A box in the raw frame's pixels (x0, y0, x1, y1) as (x, y, w, h) in the main stream's (the full field of
    view scaled; the 4:3 main crop of a 4:3 mode trims under a pixel)."""
    sx, sy = main[0] / raw[0], main[1] / raw[1]
    return [box[0] * sx, box[1] * sy, (box[2] - box[0]) * sx, (box[3] - box[1]) * sy]


def test_the_object_detection_example_gets_the_in_sensor_detections():
    out = run_detect("--frames", "5")
    assert out["input"] == [320, 320] and out["labels"] == 80 and out["raw"] == [2028, 1520]
    assert out["roi"] == [0, 0, 4056, 3040]
    records = out["records"]
    with_tensors = [r for r in records if r["detections"] is not None]
    assert len(with_tensors) >= len(records) - 1  # only the first frame can come before any result is done
    for r in with_tensors:
        period_ns = r["period_ns"]
        assert abs(period_ns - 1e9 / 30) < 1e9 / 30 / 1000  # FrameRate 30, the intrinsics' inference rate
        assert r["shapes"] == [[100, 4], [100], [100], [1]]
        result = r["insensor"][-1]
        # Timing: the result rides on a later frame, done within that frame's window on the device clock.
        assert result["seq"] < r["seq"]
        frames = r["seq"] - result["seq"]  # frame starts are whole periods apart (to the ns of exact line timing)
        assert abs(r["device_ts"] - result["timestamp_ns"] - frames * period_ns) <= frames
        assert result["input_ns"] < result["done_ns"] <= r["device_ts"] + (result["input_ns"] - result["timestamp_ns"])
        assert r["kpi"] == [-(-(result["done_ns"] - result["input_ns"]) // 1000) / 1000, 0.0]
        # The boxes the script parsed are the camera's detections, mapped into the main stream.
        want = sorted((main_box(d["box"], (2028, 1520), (640, 480)), d["score"]) for d in result["detections"]
                      if d["score"] > 0.3)
        got = sorted((d["box"], d["score"]) for d in r["detections"])
        assert len(got) == len(want) and all(d["label"] == "person" for d in r["detections"])
        for (gb, gs), (wb, ws) in zip(got, want, strict=True):
            assert gs == pytest.approx(ws, abs=1e-3)
            assert np.allclose(gb, wb, atol=1.5), (gb, wb)
    assert sum(len(r["detections"]) for r in with_tensors) >= len(with_tensors)  # people are found


def test_the_detections_are_the_network_run_on_that_frame(rollcam_picamera2):
    """What the stand-in sends for frame n is the in-sensor network run independently on frame n (made again
    from its sequence number and start), in the yolo export's layout (x first, input-tensor pixels)."""
    from rollcam.firmware.camera import FirmwareCamera
    from rollcam.firmware.insensor import load_network
    from rollcam.firmware.insensor_stage import network_input

    picamera2 = rollcam_picamera2(SOURCE)
    from picamera2.devices import IMX500

    imx500 = IMX500("/usr/share/imx500-models/imx500_network_yolov8n_pp.rpk")
    assert imx500.network_intrinsics.bbox_order == "xy" and imx500.network_intrinsics.bbox_normalization
    with picamera2.Picamera2(imx500.camera_num) as picam2:
        picam2.start(picam2.create_preview_configuration(main={"size": (320, 240)}))
        metadata = metadata_with(picam2, "RollcamInsensor")
        spec = picam2.rollcam_device.spec
    result = metadata["RollcamInsensor"][-1]
    assert spec.insensor.network == "personnet-raw" and spec.insensor.max_size == (640, 640)
    frame, samples = FirmwareCamera(spec).imager.render_samples(spec, result["seq"], result["timestamp_ns"])
    image, bits, k = network_input(spec.insensor, spec, frame, samples)
    out = load_network(spec.insensor.network).run(image, bits)
    boxes = np.asarray(out.boxes, np.float64).reshape(-1, 4) * k
    got = np.array([d["box"] for d in result["detections"]], np.float64).reshape(-1, 4)
    assert len(got) == len(boxes) > 0
    assert np.allclose(np.sort(got, axis=0), np.sort(boxes, axis=0), atol=0.01)
    outputs = imx500.get_outputs(metadata, add_batch=True)
    n = int(outputs[3][0][0])
    order = np.argsort(-np.asarray(out.scores), kind="stable")
    assert n == len(boxes)
    assert np.allclose(outputs[0][0][:n, 0], boxes[order, 0] / 2028 * 640, atol=0.01)  # x0, input pixels
    assert np.allclose(outputs[0][0][:n, 1], boxes[order, 1] / 1520 * 640, atol=0.01)  # y0
    assert np.allclose(outputs[1][0][:n], np.asarray(out.scores)[order], atol=1e-6)
    assert not outputs[1][0][n:].any()  # unused slots are zero


class OutputTensorInfo(ctypes.LittleEndianStructure):
    """libcamera's per-tensor record, written here from its definition (not imported from the stand-in)."""

    _fields_ = [("tensor_data_num", ctypes.c_uint32), ("num_dimensions", ctypes.c_uint32),
                ("size", ctypes.c_uint16 * 16)]


class CnnOutputTensorInfoExported(ctypes.LittleEndianStructure):
    _fields_ = [("network_name", ctypes.c_char * 64), ("num_tensors", ctypes.c_uint32),
                ("info", OutputTensorInfo * 16), ("frameCount", ctypes.c_uint8)]


def test_tensor_info_has_libcamera_struct_layout(rollcam_picamera2):
    rollcam_picamera2("imx500")
    from picamera2 import _cnn

    data = _cnn.tensor_info("imx500_network_ssd_mobilenetv2_fpnlite_320x320_pp", [(100, 4), (100,), (100,), (1,)],
                            frame_count=300)
    assert len(data) == ctypes.sizeof(CnnOutputTensorInfoExported) == 712
    parsed = CnnOutputTensorInfoExported.from_buffer_copy(data)
    assert parsed.network_name == b"imx500_network_ssd_mobilenetv2_fpnlite_320x320_pp"
    assert parsed.num_tensors == 4 and parsed.frameCount == 300 % 256
    assert [(t.tensor_data_num, t.num_dimensions, list(t.size)[: t.num_dimensions]) for t in parsed.info[:4]] == \
        [(400, 2, [100, 4]), (100, 1, [100]), (100, 1, [100]), (1, 1, [1])]
    assert all(t.num_dimensions == 0 for t in parsed.info[4:])


def test_network_files_resolve_through_the_table(rollcam_picamera2, tmp_path):
    rollcam_picamera2("imx500")
    from picamera2.devices.imx500 import networks

    ssd = networks.resolve("/usr/share/imx500-models/imx500_network_ssd_mobilenetv2_fpnlite_320x320_pp.rpk")
    assert (ssd.detector, ssd.input_size, ssd.bbox_order) == ("personnet-raw", (320, 320), "yx")
    with pytest.raises(RuntimeError, match=r"imx500_network_posenet\.rpk.*not one rollcam emulates"):
        networks.resolve("/usr/share/imx500-models/imx500_network_posenet.rpk")
    with pytest.raises(RuntimeError, match="does not exist"):
        networks.resolve(str(tmp_path / "mine.onnx"))
    (tmp_path / "mine.onnx").write_bytes(b"")
    assert networks.resolve(str(tmp_path / "mine.onnx")).detector == f"onnx:{tmp_path / 'mine.onnx'}"
    assert networks.resolve("personnet?conf=0.2").detector == "personnet?conf=0.2"
    doc = Path(__file__).resolve().parents[1] / "docs" / "picamera2.md"
    assert all(f"`{stem}`" in doc.read_text() for stem in networks.ZOO)


def test_imx500_needs_an_imx500_camera(rollcam_picamera2):
    rollcam_picamera2("imx219")
    from picamera2.devices import IMX500

    with pytest.raises(RuntimeError, match=r"dev-node not found.*ROLLCAM_PICAMERA2"):
        IMX500("/usr/share/imx500-models/imx500_network_ssd_mobilenetv2_fpnlite_320x320_pp.rpk")


def test_inference_roi_programs_the_in_sensor_stage(rollcam_picamera2):
    picamera2 = rollcam_picamera2(SOURCE)
    from picamera2.devices import IMX500

    imx500 = IMX500("/usr/share/imx500-models/imx500_network_ssd_mobilenetv2_fpnlite_320x320_pp.rpk")
    with picamera2.Picamera2(imx500.camera_num) as picam2:
        picam2.configure(picam2.create_preview_configuration(main={"size": (640, 480)}))
        assert picam2.rollcam_device.spec.insensor.roi is None
        imx500.set_auto_aspect_ratio()  # 320x320: the centred square of the 4056x3040 array
        assert imx500.config["roi"] == (508, 0, 3040, 3040)
        assert picam2.rollcam_device.spec.insensor.roi == (254, 0, 1520, 1520)  # in the 2028x1520 mode's pixels
        picam2.start()
        request = picam2.capture_request()
        try:
            assert imx500.get_roi_scaled(request) == (80, 0, 480, 480)
        finally:
            request.release()
        metadata = metadata_with(picam2, "RollcamInsensor")
    result = metadata["RollcamInsensor"][-1]
    assert result["input_size"][0] <= 320 and result["input_size"][1] <= 320
    assert all(d["box"][0] >= 254 and d["box"][2] <= 254 + 1520 for d in result["detections"])


def test_nanodet_decoder_recovers_a_box(rollcam_picamera2):
    rollcam_picamera2("imx500")
    from picamera2.devices.imx500 import postprocess_nanodet_detection
    from picamera2.devices.imx500.postprocess_nanodet import anchors

    a = anchors()[0]
    raw = np.full((1, len(a), 80 + 32), -20.0, np.float32)
    cell = int(np.flatnonzero((a[:, 0] == 200) & (a[:, 1] == 160) & (a[:, 2] == 8))[0])
    raw[0, cell, 0] = 10.0  # a confident person
    for side, bins in enumerate((3, 2, 4, 5)):  # left, top, right, bottom distances in strides
        raw[0, cell, 80 + side * 8 + bins] = 30.0
    boxes, scores, classes = postprocess_nanodet_detection(raw, conf=0.5)[0]
    assert classes.tolist() == [0] and scores[0] == pytest.approx(1 / (1 + np.exp(-10.0)))
    assert np.allclose(boxes[0], [160 - 16, 200 - 24, 160 + 40, 200 + 32], atol=1e-3)  # y0, x0, y1, x1


# ------------------------------------------------------------------------------------------- classification
MOBILENET = "/usr/share/imx500-models/imx500_network_mobilenet_v2.rpk"


def test_the_classification_example_shows_the_networks_top_three(tmp_path):
    """picamera2's classification example (its flow, unchanged): the 1000-class output tensor, softmax, the top 3
    by score with their ImageNet-style labels (a 1001-line file: the background label is skipped)."""
    labels = tmp_path / "labels.txt"
    labels.write_text("\n".join(["background", *(f"class{i}" for i in range(1000))]))
    done = subprocess.run([sys.executable, str(EXAMPLES / "imx500_classify.py"), "--labels", str(labels),
                           "--softmax", "--frames", "4"], env=standin_env([SOURCE]), cwd=EXAMPLES,
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["input"] == [224, 224]
    fresh = [r for r in out["records"] if r["fresh"]]
    assert len(fresh) >= len(out["records"]) - 1 and all(r["input_tensor"] for r in fresh)
    for r in fresh:
        assert r["insensor"][-1]["network"] == "colournet" and r["insensor"][-1]["seq"] < r["seq"]
        assert r["insensor"][-1]["tensor_shapes"] == {"logits": [1000]}
        scores = [s for _, s, _ in r["top"]]
        assert len(r["top"]) == 3 and scores == sorted(scores, reverse=True) and 0 < sum(scores) <= 1
        assert all(label == f"class{idx}" for idx, _, label in r["top"])


def test_the_classifier_ran_on_that_frames_input_tensor(rollcam_picamera2):
    """The logits a request carries are colournet's on the picture of its CnnInputTensor, and that tensor is the
    IMX500 input tensor of the frame the result names (made again from its sequence number and start)."""
    from rollcam.firmware.insensor_stage import tensor_input
    from rollcam.host.detectors.onchip import ColourNet

    picamera2 = rollcam_picamera2(SOURCE)
    from picamera2.devices import IMX500
    from picamera2.devices.imx500.postprocess import softmax

    imx500 = IMX500(MOBILENET)
    assert imx500.network_intrinsics.task == "classification"
    with picamera2.Picamera2(imx500.camera_num) as picam2:
        picam2.start(picam2.create_preview_configuration(main={"size": (320, 240)}))
        metadata = metadata_with(picam2, "CnnOutputTensor")
        spec = picam2.rollcam_device.spec
    outputs = imx500.get_outputs(metadata)
    assert imx500.get_output_shapes(metadata) == [[1000]] and outputs[0].shape == (1000,)
    tensor = np.asarray(metadata["CnnInputTensor"], np.uint8)
    picture = imx500.input_tensor_image(tensor)
    assert np.allclose(outputs[0], ColourNet().logits(picture), atol=1e-5)
    result = metadata["RollcamInsensor"][-1]
    frame, _samples = FirmwareCamera(spec).imager.render_samples(spec, result["seq"], result["timestamp_ns"])
    made, seen, _ = tensor_input(spec.insensor, spec, frame)
    assert np.array_equal(spec.insensor.tensor.planes(made).ravel(), tensor) and np.array_equal(seen, picture)
    top = np.argsort(-softmax(outputs[0]))[:3]
    assert np.allclose(softmax(outputs[0])[top].sum(), np.sort(softmax(ColourNet().logits(picture)))[-3:].sum())


# ------------------------------------------------------------------------------------------- segmentation
DEEPLAB = "/usr/share/imx500-models/imx500_network_deeplabv3plus.rpk"


def test_the_segmentation_example_draws_a_mask_per_class(tmp_path):
    """picamera2's segmentation example (its flow, unchanged): the (513, 513) class map, one RGBA mask per class
    found, set as the preview overlay."""
    colours = tmp_path / "colours.txt"
    colours.write_text("\n".join(f"{(37 * i) % 256} {(91 * i) % 256} {(53 * i) % 256} 255" for i in range(21)))
    done = subprocess.run([sys.executable, str(EXAMPLES / "imx500_segment.py"), "--colours", str(colours),
                           "--frames", "3"], env=standin_env([SOURCE]), cwd=EXAMPLES,
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["input"] == [513, 513]
    fresh = [r for r in out["records"] if r["insensor"]]
    assert len(fresh) >= len(out["records"]) - 1
    for r in fresh:
        assert r["insensor"][-1]["network"] == "colourseg"
        assert r["insensor"][-1]["tensor_shapes"] == {"mask": [513, 513]}
        assert r["overlay"] == [513, 513, 4] and r["classes"]
        assert all(1 <= int(c) <= 20 for c in r["classes"]) and sum(r["classes"].values()) < 513 * 513


def test_the_segmenter_ran_on_that_frames_input_tensor(rollcam_picamera2):
    from rollcam.firmware.insensor_stage import tensor_input
    from rollcam.host.detectors.onchip import ColourSeg

    picamera2 = rollcam_picamera2(SOURCE)
    from picamera2.devices import IMX500

    imx500 = IMX500(DEEPLAB)
    assert imx500.network_intrinsics.task == "segmentation" and imx500.get_input_size() == (513, 513)
    with picamera2.Picamera2(imx500.camera_num) as picam2:
        picam2.start(picam2.create_preview_configuration(main={"size": (320, 240)}))
        metadata = metadata_with(picam2, "CnnOutputTensor")
        spec = picam2.rollcam_device.spec
    mask = imx500.get_outputs(metadata)[0]
    assert mask.shape == (513, 513) and imx500.get_output_shapes(metadata) == [[513, 513]]
    picture = imx500.input_tensor_image(np.asarray(metadata["CnnInputTensor"], np.uint8))
    assert np.array_equal(mask, ColourSeg().mask(picture))
    assert 0 < np.count_nonzero(mask) < mask.size  # colourful people on a grey street
    result = metadata["RollcamInsensor"][-1]
    frame, _samples = FirmwareCamera(spec).imager.render_samples(spec, result["seq"], result["timestamp_ns"])
    _, seen, _ = tensor_input(spec.insensor, spec, frame)
    assert np.array_equal(seen, picture)


# ------------------------------------------------------------------------------------------- pose estimation
def test_the_pose_example_finds_the_in_sensor_people_and_their_keypoints(tmp_path):
    """picamera2's HigherHRNet pose example (its flow, unchanged): postprocess_higherhrnet groups the on-chip
    outputs into people in a 640x480 window and COCODrawer draws them. posenet's people are personnet's
    detections with a template skeleton, so each person the script shows is a detection the camera made, its
    keypoints the template in that box (to the output grid's 2 input pixels)."""
    from rollcam.host.detectors.onchip import POSE_TEMPLATE

    labels = tmp_path / "coco_labels.txt"
    labels.write_text("person\n")
    done = subprocess.run([sys.executable, str(EXAMPLES / "imx500_pose.py"), "--labels", str(labels),
                           "--frames", "3"], env=standin_env([SOURCE]), cwd=EXAMPLES,
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["input"] == [384, 288]
    x_off, _, roi_w, roi_h = out["roi"]  # set_auto_aspect_ratio: the array's 4:3 centre, pixel-array units
    fresh = [r for r in out["records"] if r["fresh"]]
    assert len(fresh) >= len(out["records"]) - 1
    for r in fresh:
        result = r["insensor"][-1]
        assert result["network"] == "posenet"
        dets = sorted((d for d in result["detections"] if d["score"] > 0.3), key=lambda d: -d["score"])
        assert len(r["scores"]) == len(dets) > 0
        assert np.allclose(r["scores"], [d["score"] for d in dets], atol=1e-4)
        for kps, d in zip(r["keypoints"], dets, strict=True):
            x0, y0, x1, y1 = d["box"]  # the 2028x1520 mode's pixels: half the array's
            sx, sy = 640 / (roi_w / 2), 480 / (roi_h / 2)
            want_x = (x0 + POSE_TEMPLATE[:, 0] * (x1 - x0) - x_off / 2) * sx
            want_y = (y0 + POSE_TEMPLATE[:, 1] * (y1 - y0)) * sy
            got = np.asarray(kps)
            assert np.all(np.abs(got[:, 0] - want_x) <= 4) and np.all(np.abs(got[:, 1] - want_y) <= 4)
            assert np.allclose(got[:, 2], d["score"], atol=1e-4)
