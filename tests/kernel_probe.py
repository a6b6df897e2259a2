"""Run inside the kernel tests' guest: read frames through one of rollcam's camera sources, as a user's program
would, and write what each ``Frame`` says as JSON for the host side of the test to check.

Usage: ``python kernel_probe.py URI COUNT OUT.json``. Per frame: the SHA-1 of its pixels, its size, timestamp,
exposure, line time, the host's clock at capture and every row's time (``row_times_ns``, or null).
"""

from __future__ import annotations

import hashlib
import json
import sys

from rollcam.host.sources import open_camera


def main(uri: str, count: int, out: str) -> None:
    """Read ``count`` frames from ``uri`` and write them to ``out``."""
    frames = []
    with open_camera(uri) as cam:
        for _ in range(count):
            f = cam.read()
            frames.append({
                "sha1": hashlib.sha1(f.data.tobytes()).hexdigest(),
                "shape": list(f.data.shape),
                "timestamp_ns": int(f.timestamp_ns),
                "exposure_ns": int(f.exposure_ns),
                "line_time_ns": int(f.line_time_ns),
                "shutter": f.shutter,
                "host_ns": int(f.meta.get("host_ns", 0)),
                "row_times_ns": None if f.row_times_ns is None else [int(t) for t in f.row_times_ns],
            })
        info = cam.info()  # after the frames: the row timing follows the delivered size
    with open(out, "w") as fh:
        json.dump({"info": info, "frames": frames}, fh)


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), sys.argv[3])
