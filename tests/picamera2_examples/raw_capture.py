#!/usr/bin/python3
# Raw captures as picamera2's raw.py does them: an unpacked raw stream, then a sensor mode's own (packed)
# format taken from sensor_modes. Prints one JSON line.
import json

import numpy as np
from picamera2 import Picamera2, Preview

out = {}
picam2 = Picamera2()
picam2.start_preview(Preview.NULL)

config = picam2.create_preview_configuration(main={"size": (320, 240)}, raw={"format": "SRGGB10", "size": (640, 480)})
picam2.configure(config)
picam2.start()
raw = picam2.capture_array("raw")
samples = raw.view(np.uint16)
out["unpacked"] = {"shape": list(raw.shape), "dtype": str(raw.dtype), "max": int(samples.max()),
                   "mean": float(samples.mean()), "stream": dict(picam2.stream_configuration("raw"))}
picam2.stop()

mode = picam2.sensor_modes[0]
sensor = {"output_size": mode["size"], "bit_depth": mode["bit_depth"]}
picam2.configure(picam2.create_preview_configuration(main={"size": (320, 240)}, raw=mode, sensor=sensor))
picam2.start()
request = picam2.capture_request()
packed = request.make_array("raw")
out["packed"] = {"shape": list(packed.shape), "dtype": str(packed.dtype), "mode": str(mode["format"]),
                 "size": list(mode["size"]), "stream": picam2.stream_configuration("raw")["format"],
                 "timestamp": request.get_metadata()["SensorTimestamp"]}
request.release()
picam2.close()
print(json.dumps(out))
