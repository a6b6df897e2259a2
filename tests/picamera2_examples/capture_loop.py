#!/usr/bin/python3
# A headless capture loop as picamera2's examples write one (opencv_face_detect.py, capture_headless.py):
# nothing here knows of rollcam. Prints one JSON line for the test that runs it.
import json
import sys

import cv2
from picamera2 import Picamera2

picam2 = Picamera2()
config = picam2.create_preview_configuration(main={"format": "XRGB8888", "size": (320, 240)},
                                             controls={"FrameRate": 15})
picam2.configure(config)
picam2.start()

shapes, means, alphas = [], [], []
for _ in range(6):
    im = picam2.capture_array()
    grey = cv2.cvtColor(im, cv2.COLOR_BGRA2GRAY)
    shapes.append(list(im.shape))
    means.append(float(grey.mean()))
    alphas.append(int(im[..., 3].min()))

metadata = picam2.capture_file(sys.argv[1])
picam2.stop()
print(json.dumps({"shapes": shapes, "means": means, "alphas": alphas, "file_exposure": metadata["ExposureTime"],
                  "config": {k: v for k, v in picam2.camera_configuration()["main"].items()},
                  "model": picam2.camera_properties["Model"]}))
picam2.close()
