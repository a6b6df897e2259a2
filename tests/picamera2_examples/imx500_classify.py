#!/usr/bin/python3
# Classification on a Raspberry Pi AI Camera, written as picamera2's imx500_classification_demo.py is: the
# network loaded before Picamera2 opens the camera, the output tensor of each request parsed in a pre-callback
# (softmax when the intrinsics ask, the top 3 by score) and drawn on the main stream. No preview window; it
# prints one JSON line of what each request gave.
import argparse
import json
import sys

import cv2
import numpy as np
from picamera2 import CompletedRequest, MappedArray, Picamera2
from picamera2.devices import IMX500
from picamera2.devices.imx500 import NetworkIntrinsics
from picamera2.devices.imx500.postprocess import softmax

last_detections = []
LABELS = None
records = []


class Classification:
    def __init__(self, idx: int, score: float):
        self.idx = idx
        self.score = score


def get_label(request: CompletedRequest, idx: int) -> str:
    global LABELS
    if LABELS is None:
        LABELS = intrinsics.labels
        assert len(LABELS) in [1000, 1001], "Labels file should contain 1000 or 1001 labels."
        output_tensor_size = imx500.get_output_shapes(request.get_metadata())[0][0]
        if output_tensor_size == 1000:
            LABELS = LABELS[1:]  # Ignore the background label if present
    return LABELS[idx]


def parse_and_draw_classification_results(request: CompletedRequest):
    results = parse_classification_results(request)
    draw_classification_results(request, results)
    md = request.get_metadata()
    records.append({"seq": md["RollcamSequence"], "fresh": md.get("CnnOutputTensor") is not None,
                    "top": [[int(r.idx), float(r.score), get_label(request, r.idx)] for r in results],
                    "insensor": md.get("RollcamInsensor"), "input_tensor": md.get("CnnInputTensor") is not None})


def parse_classification_results(request: CompletedRequest) -> list[Classification]:
    global last_detections
    np_outputs = imx500.get_outputs(request.get_metadata())
    if np_outputs is None:
        return last_detections
    np_output = np_outputs[0]
    if intrinsics.softmax:
        np_output = softmax(np_output)
    top_indices = np.argpartition(-np_output, 3)[:3]  # Get top 3 indices with the highest scores
    top_indices = top_indices[np.argsort(-np_output[top_indices])]  # Sort the top 3 indices by their scores
    last_detections = [Classification(index, np_output[index]) for index in top_indices]
    return last_detections


def draw_classification_results(request: CompletedRequest, results: list[Classification], stream: str = "main"):
    with MappedArray(request, stream) as m:
        if intrinsics.preserve_aspect_ratio:
            b_x, b_y, b_w, b_h = imx500.get_roi_scaled(request)
            cv2.rectangle(m.array, (b_x, b_y), (b_x + b_w, b_y + b_h), (255, 0, 0, 0))
            text_left, text_top = b_x, b_y + 20
        else:
            text_left, text_top = 0, 0
        for index, result in enumerate(results):
            label = get_label(request, idx=result.idx)
            text = f"{label}: {result.score:.3f}"
            cv2.putText(m.array, text, (text_left + 5, text_top + 15 + index * 20),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 255), 1)


parser = argparse.ArgumentParser()
parser.add_argument("--model", type=str, default="/usr/share/imx500-models/imx500_network_mobilenet_v2.rpk")
parser.add_argument("-s", "--softmax", action=argparse.BooleanOptionalAction)
parser.add_argument("-r", "--preserve-aspect-ratio", action=argparse.BooleanOptionalAction)
parser.add_argument("--labels", type=str)
parser.add_argument("--frames", type=int, default=6)
args = parser.parse_args()

imx500 = IMX500(args.model)  # before Picamera2, as on a Pi
intrinsics = imx500.network_intrinsics
if not intrinsics:
    intrinsics = NetworkIntrinsics()
    intrinsics.task = "classification"
elif intrinsics.task != "classification":
    print("Network is not a classification task", file=sys.stderr)
    sys.exit(1)
for key, value in vars(args).items():
    if key == "labels" and value is not None:
        with open(value) as f:
            intrinsics.labels = f.read().splitlines()
    elif hasattr(intrinsics, key) and value is not None:
        setattr(intrinsics, key, value)
intrinsics.update_with_defaults()

picam2 = Picamera2(imx500.camera_num)
config = picam2.create_preview_configuration(main={"size": (320, 240)},
                                             controls={"FrameRate": intrinsics.inference_rate}, buffer_count=12)
imx500.show_network_fw_progress_bar()
picam2.start(config, show_preview=False)
if intrinsics.preserve_aspect_ratio:
    imx500.set_auto_aspect_ratio()
picam2.pre_callback = parse_and_draw_classification_results
while len(records) < args.frames:
    picam2.capture_metadata()
picam2.stop()
picam2.close()
print(json.dumps({"input": list(imx500.get_input_size()), "roi": list(imx500.config["roi"]),
                  "records": records[: args.frames]}))
