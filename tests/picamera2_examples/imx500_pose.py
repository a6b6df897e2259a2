#!/usr/bin/python3
# Pose estimation on a Raspberry Pi AI Camera, written as picamera2's imx500_pose_estimation_higherhrnet_demo.py
# is: the network loaded before Picamera2 opens the camera, each request's outputs decoded by
# postprocess_higherhrnet (grouped on chip) into people's keypoints, scores and boxes in a 640x480 window, and
# drawn by COCODrawer on the main stream. No preview window; it prints one JSON line of what each request gave.
import argparse
import json

import numpy as np
from picamera2 import CompletedRequest, MappedArray, Picamera2
from picamera2.devices import IMX500
from picamera2.devices.imx500.postprocess import COCODrawer
from picamera2.devices.imx500.postprocess_highernet import postprocess_higherhrnet

last_boxes = None
last_scores = None
last_keypoints = None
WINDOW_SIZE_H_W = (480, 640)
records = []


def ai_output_tensor_parse(metadata: dict):
    global last_boxes, last_scores, last_keypoints
    np_outputs = imx500.get_outputs(metadata=metadata, add_batch=True)
    if np_outputs is not None:
        keypoints, scores, boxes = postprocess_higherhrnet(outputs=np_outputs,
                                                           img_size=WINDOW_SIZE_H_W,
                                                           img_w_pad=(0, 0),
                                                           img_h_pad=(0, 0),
                                                           detection_threshold=args.detection_threshold,
                                                           network_postprocess=True)

        if scores is not None and len(scores) > 0:
            last_keypoints = np.reshape(np.stack(keypoints, axis=0), (len(scores), 17, 3))
            last_boxes = [np.array(b) for b in boxes]
            last_scores = np.array(scores)
    return last_boxes, last_scores, last_keypoints


def ai_output_tensor_draw(request: CompletedRequest, boxes, scores, keypoints, stream="main"):
    with MappedArray(request, stream) as m:
        if boxes is not None and len(boxes) > 0:
            drawer.annotate_image(m.array, boxes, scores,
                                  np.zeros(scores.shape), keypoints, args.detection_threshold,
                                  args.detection_threshold, request.get_metadata(), picam2, stream)


def picamera2_pre_callback(request: CompletedRequest):
    boxes, scores, keypoints = ai_output_tensor_parse(request.get_metadata())
    ai_output_tensor_draw(request, boxes, scores, keypoints)
    md = request.get_metadata()
    records.append({"seq": md["RollcamSequence"], "insensor": md.get("RollcamInsensor"),
                    "fresh": md.get("CnnOutputTensor") is not None,
                    "keypoints": None if keypoints is None else keypoints.tolist(),
                    "scores": None if scores is None else scores.tolist(),
                    "boxes": None if boxes is None else [b.tolist() for b in boxes]})


parser = argparse.ArgumentParser()
parser.add_argument("--model", type=str, default="/usr/share/imx500-models/imx500_network_higherhrnet_coco.rpk")
parser.add_argument("--fps", type=int, default=11)
parser.add_argument("--detection-threshold", type=float, default=0.3)
parser.add_argument("--labels", type=str, required=True)
parser.add_argument("--frames", type=int, default=4)
args = parser.parse_args()

imx500 = IMX500(args.model)  # before Picamera2, as on a Pi
with open(args.labels) as f:
    categories = [c for c in f.read().split("\n") if c and c != "-"]
drawer = COCODrawer(categories, imx500, needs_rescale_coords=False)

picam2 = Picamera2(imx500.camera_num)
config = picam2.create_preview_configuration(main={"size": (640, 480)}, controls={"FrameRate": args.fps},
                                             buffer_count=28)
imx500.show_network_fw_progress_bar()
picam2.start(config, show_preview=False)
imx500.set_auto_aspect_ratio()
picam2.pre_callback = picamera2_pre_callback
while len(records) < args.frames:
    picam2.capture_metadata()
picam2.stop()
picam2.close()
print(json.dumps({"input": list(imx500.get_input_size()), "roi": list(imx500.config["roi"]),
                  "records": records[: args.frames]}))
