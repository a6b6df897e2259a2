#!/usr/bin/python3
# A video configuration with a low-resolution YUV stream, read request by request with its metadata, as
# picamera2's capture_motion.py and metadata_with_image.py do. Prints one JSON line.
import json

from picamera2 import Picamera2

frames = []
with Picamera2() as picam2:
    config = picam2.create_video_configuration(main={"size": (320, 240), "format": "RGB888"},
                                               lores={"size": (160, 120), "format": "YUV420"},
                                               controls={"FrameRate": 20})
    picam2.configure(config)
    picam2.start()
    for _ in range(10):
        with picam2.captured_request() as request:
            metadata = request.get_metadata()
            lores = request.make_array("lores")
            main = request.make_array("main")
        frames.append({"ts": metadata["SensorTimestamp"], "duration": metadata["FrameDuration"],
                       "exposure": metadata["ExposureTime"], "gain": metadata["AnalogueGain"],
                       "digital": metadata["DigitalGain"], "black": list(metadata["SensorBlackLevels"]),
                       "line_ns": metadata["RollcamLineTime"], "readout": metadata["RollcamReadout"],
                       "period_ns": metadata["RollcamFrameDurationNs"], "lores": list(lores.shape),
                       "main": list(main.shape), "y_mean": float(lores[:120].mean())})
    picam2.stop()
print(json.dumps(frames))
