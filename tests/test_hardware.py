"""Real cameras, when attached: marked ``hardware`` and skipped otherwise."""

from __future__ import annotations

import glob

import pytest
from rollcam.host import open_camera

pytestmark = pytest.mark.hardware


def test_v4l2_camera_delivers_timed_frames():
    nodes = sorted(glob.glob("/dev/video*"))
    if not nodes:
        pytest.skip("no /dev/video* camera attached")
    with open_camera(f"v4l2:{nodes[0]}?sensor=imx219") as src:
        frames = [src.read() for _ in range(3)]
    assert all(f.data.ndim == 3 for f in frames)
    assert frames[2].timestamp_ns > frames[0].timestamp_ns and frames[0].line_time_ns > 0


def test_oak_delivers_device_timed_frames():
    dai = pytest.importorskip("depthai")
    if not dai.Device.getAllAvailableDevices():
        pytest.skip("no OAK attached")
    with open_camera("oak:?size=1280x720") as src:
        frames = [src.read() for _ in range(3)]
    assert [f.sequence for f in frames] == sorted({f.sequence for f in frames})
    assert frames[0].line_time_ns > 0 and frames[0].exposure_ns > 0
