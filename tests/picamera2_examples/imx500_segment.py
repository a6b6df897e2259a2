#!/usr/bin/python3
# Semantic segmentation on a Raspberry Pi AI Camera, written as picamera2's imx500_segmentation_demo.py is: the
# network loaded before Picamera2 opens the camera, each request's output tensor (the class of every input
# tensor pixel) made into one RGBA mask per class found and set as the preview overlay. No preview window; it
# prints one JSON line of what each request gave.
import argparse
import json
import sys

import numpy as np
from picamera2 import CompletedRequest, Picamera2
from picamera2.devices import IMX500
from picamera2.devices.imx500 import NetworkIntrinsics

parser = argparse.ArgumentParser()
parser.add_argument("--model", type=str, default="/usr/share/imx500-models/imx500_network_deeplabv3plus.rpk")
parser.add_argument("--colours", type=str, required=True)
parser.add_argument("--frames", type=int, default=4)
args = parser.parse_args()
COLOURS = np.loadtxt(args.colours)
records = []


def create_and_draw_masks(request: CompletedRequest):
    masks = create_masks(request)
    draw_masks(masks)
    md = request.get_metadata()
    records.append({"seq": md["RollcamSequence"], "insensor": md.get("RollcamInsensor"),
                    "classes": {str(int(i)): int(v[:, :, 3].astype(bool).sum()) for i, v in masks.items()},
                    "overlay": None if picam2.overlay is None else list(picam2.overlay.shape)})


def create_masks(request: CompletedRequest) -> dict[int, np.ndarray]:
    res = {}
    np_outputs = imx500.get_outputs(metadata=request.get_metadata())
    input_w, input_h = imx500.get_input_size()
    if np_outputs is None:
        return res
    mask = np_outputs[0]
    found_indices = np.unique(mask)

    for i in found_indices:
        if i == 0:
            continue
        output_shape = [input_h, input_w, 4]
        colour = [(0, 0, 0, 0), COLOURS[int(i)]]
        colour[1][3] = 150  # update the alpha value here, to save setting it later
        overlay = np.array(mask == i, dtype=np.uint8)
        overlay = np.array(colour)[overlay].reshape(output_shape).astype(np.uint8)
        res[i] = overlay
    return res


def draw_masks(masks: dict[int, np.ndarray]):
    if not masks:
        return
    input_w, input_h = imx500.get_input_size()
    output_shape = [input_h, input_w, 4]
    overlay = np.zeros(output_shape, dtype=np.uint8)
    if masks:
        for v in masks.values():
            overlay += v
        picam2.set_overlay(overlay)


imx500 = IMX500(args.model)  # before Picamera2, as on a Pi
intrinsics = imx500.network_intrinsics
if not intrinsics:
    intrinsics = NetworkIntrinsics()
    intrinsics.task = "segmentation"
elif intrinsics.task != "segmentation":
    print("Network is not a segmentation task", file=sys.stderr)
    sys.exit(1)
intrinsics.update_with_defaults()

picam2 = Picamera2(imx500.camera_num)
config = picam2.create_preview_configuration(main={"size": (320, 240)},
                                             controls={"FrameRate": intrinsics.inference_rate}, buffer_count=12)
imx500.show_network_fw_progress_bar()
picam2.start(config, show_preview=False)
picam2.pre_callback = create_and_draw_masks
while len(records) < args.frames:
    picam2.capture_metadata()
picam2.stop()
picam2.close()
print(json.dumps({"input": list(imx500.get_input_size()), "records": records[: args.frames]}))
