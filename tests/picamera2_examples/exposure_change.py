#!/usr/bin/python3
# Fixed exposure, then a shorter one set while running (picamera2's exposure_fixed.py and controls.py):
# frames darken from the frame whose metadata reports the new exposure. Prints one JSON line.
import json

from picamera2 import Picamera2

picam2 = Picamera2()
picam2.configure(picam2.create_preview_configuration(
    main={"size": (320, 240), "format": "RGB888"},
    controls={"FrameRate": 10, "ExposureTime": 20000, "AnalogueGain": 1.0}))
picam2.start()

records = []


def grab():
    request = picam2.capture_request()
    image = request.make_array("main")
    metadata = request.get_metadata()
    request.release()
    records.append({"exposure": metadata["ExposureTime"], "mean": float(image.mean()),
                    "ts": metadata["SensorTimestamp"], "duration": metadata["FrameDuration"],
                    "phase": phase})


phase = "long"
for _ in range(3):
    grab()
phase = "short"
picam2.set_controls({"ExposureTime": 2000})
for _ in range(4):
    grab()
picam2.close()
print(json.dumps(records))
