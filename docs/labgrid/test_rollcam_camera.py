"""A labgrid test against an emulated rollcam camera (docs/labs.md). Run it with labgrid's pytest plugin:

    pytest --lg-env docs/labgrid/rollcam-env.yaml docs/labgrid/test_rollcam_camera.py

labgrid hands the test the ``target`` of the environment file; its ``VideoProtocol`` driver is rollcam's.
"""

import numpy as np
import pytest
from rollcam.host import open_camera


@pytest.fixture
def camera(target):
    return target.get_driver("VideoProtocol")  # found by the protocol it implements, and activated


def test_frames_are_the_emulators_own(camera):
    """The frames labgrid's driver gives are rollcam's for the same camera and seed, the injected drop included."""
    got = camera.frames(5)
    with open_camera(camera.camera.uri) as reference:
        want = [reference.read() for _ in range(5)]
    assert [f.sequence for f in got] == [f.sequence for f in want] == [0, 2, 3, 5, 6]  # two frames dropped
    assert [bool(f.meta.get("error")) for f in got] == [False, True, False, True, False]  # and two flagged
    for g, w in zip(got, want, strict=True):
        assert np.array_equal(g.data, w.data), f"frame {g.sequence} differs"
        assert (g.timestamp_ns, g.line_time_ns) == (w.timestamp_ns, w.line_time_ns)


def test_a_control_changes_the_next_frame(camera):
    """A shorter exposure, set through the driver, darkens the next frame."""
    before = camera.read().data.mean()
    exposure = camera.get_control("exposure")
    assert camera.set_control("exposure", exposure // 8) == exposure // 8
    assert camera.read().data.mean() < 0.5 * before


def test_qualities_name_the_cameras_caps(camera):
    default, qualities = camera.get_qualities()
    assert default == "native"
    assert dict(qualities)["native"].startswith("video/x-raw,format=BGR,width=320,height=240,framerate=")
