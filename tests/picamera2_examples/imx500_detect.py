#!/usr/bin/python3
# Object detection on a Raspberry Pi AI Camera, written as picamera2's imx500_object_detection_demo.py is:
# the network loaded before Picamera2 opens the camera, the output tensors parsed from each frame's metadata
# (boxes, scores, classes of a post-processed network) and mapped into the main stream's pixels. No preview
# window; it prints one JSON line of what each request gave.
import argparse
import json
import sys

from picamera2 import Picamera2
from picamera2.devices import IMX500
from picamera2.devices.imx500 import NetworkIntrinsics, postprocess_nanodet_detection

parser = argparse.ArgumentParser()
parser.add_argument("--model",
                    default="/usr/share/imx500-models/imx500_network_ssd_mobilenetv2_fpnlite_320x320_pp.rpk")
parser.add_argument("--bbox-normalization", action=argparse.BooleanOptionalAction)
parser.add_argument("--bbox-order", choices=["yx", "xy"], default="yx")
parser.add_argument("--threshold", type=float, default=0.3)
parser.add_argument("--frames", type=int, default=8)
parser.add_argument("-r", "--preserve-aspect-ratio", action=argparse.BooleanOptionalAction)
args = parser.parse_args()

imx500 = IMX500(args.model)  # before Picamera2, as on a Pi
intrinsics = imx500.network_intrinsics or NetworkIntrinsics()
if intrinsics.task != "object detection":
    print("Network is not an object detection task", file=sys.stderr)
    sys.exit(1)
for key, value in vars(args).items():
    if hasattr(intrinsics, key) and value is not None:
        setattr(intrinsics, key, value)
intrinsics.update_with_defaults()


def parse_detections(metadata):
    outputs = imx500.get_outputs(metadata, add_batch=True)
    if outputs is None:
        return None
    _, input_h = imx500.get_input_size()
    if intrinsics.postprocess == "nanodet":
        boxes, scores, classes = postprocess_nanodet_detection(outputs=outputs[0], conf=args.threshold)[0]
    else:
        boxes, scores, classes = outputs[0][0], outputs[1][0], outputs[2][0]
        if intrinsics.bbox_normalization:
            boxes = boxes / input_h
        if intrinsics.bbox_order == "xy":
            boxes = boxes[:, [1, 0, 3, 2]]
    labels = intrinsics.labels
    return [{"box": list(imx500.convert_inference_coords(box, metadata, picam2)), "label": labels[int(c)],
             "score": round(float(s), 4)}
            for box, s, c in zip(boxes, scores, classes, strict=True) if s > args.threshold]


picam2 = Picamera2(imx500.camera_num)
config = picam2.create_preview_configuration(main={"size": (640, 480)},
                                             controls={"FrameRate": intrinsics.inference_rate}, buffer_count=12)
imx500.show_network_fw_progress_bar()
picam2.start(config, show_preview=False)
if intrinsics.preserve_aspect_ratio:
    imx500.set_auto_aspect_ratio()

records = []
while len(records) < args.frames:
    request = picam2.capture_request()
    try:
        metadata = request.get_metadata()
        records.append({"ts": metadata["SensorTimestamp"], "seq": metadata["RollcamSequence"],
                        "device_ts": metadata["RollcamDeviceTimestamp"],
                        "period_ns": metadata["RollcamFrameDurationNs"], "detections": parse_detections(metadata),
                        "kpi": imx500.get_kpi_info(metadata), "shapes": imx500.get_output_shapes(metadata),
                        "insensor": metadata.get("RollcamInsensor"), "crop": list(metadata["ScalerCrop"]),
                        "main": list(request.make_array("main").shape)})
    finally:
        request.release()
raw_size = list(picam2.camera_configuration()["raw"]["size"])
picam2.stop()
picam2.close()
print(json.dumps({"input": list(imx500.get_input_size()), "labels": len(intrinsics.labels), "raw": raw_size,
                  "roi": list(imx500.config["roi"]), "records": records}))
