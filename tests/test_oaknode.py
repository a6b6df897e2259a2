"""The depthai host node on a real host-only depthai pipeline (no device needed)."""

from __future__ import annotations

import datetime

import pytest
from rollcam.common.errors import SourceError
from rollcam.host import open_camera

dai = pytest.importorskip("depthai")

URI = "emu:imx378?size=320x180&seed=3&pedestrians=5"


def test_host_pipeline_receives_emulated_imgframes():
    from rollcam.host.integrations.oaknode import EmulatedCamera

    with open_camera(URI + "&frames=3") as src:
        expected = list(src)
    got = []
    with dai.Pipeline(False) as pipeline:
        cam = pipeline.create(EmulatedCamera).build(URI, frames=3)
        queue = cam.out.createOutputQueue()
        pipeline.start()
        while len(got) < 3:
            msg = queue.get()
            start = msg.getTimestampDevice(dai.CameraExposureOffset.START)
            got.append((msg.getSequenceNum(), start, msg.getTimestampDevice(), msg.getExposureTime(),
                        msg.getCvFrame(), msg.getType()))
    assert cam.error is None
    us = datetime.timedelta(microseconds=1)
    for (seq, start, end, exposure, img, kind), frame in zip(got, expected, strict=True):
        assert seq == frame.sequence and kind == dai.ImgFrame.Type.BGR888i
        # depthai's plain stamp is the end of exposure; START is the frame's start of exposure, in whole us
        assert start // us == frame.timestamp_ns // 1000 and exposure // us == frame.exposure_ns // 1000 > 0
        assert end - start == exposure
        assert (img == frame.data).all()
        assert cam.truth[seq] == frame.objects


def test_bad_uri_fails_in_build():
    from rollcam.host.integrations.oaknode import EmulatedCamera

    with dai.Pipeline(False) as pipeline, pytest.raises(SourceError, match="nope"):
        pipeline.create(EmulatedCamera).build("emu:nope")


@pytest.mark.parametrize("limit", [1, 4])
def test_readme_loop_ends_after_the_last_frame(limit):
    """The README's loop, as written: every frame arrives, then isRunning() is False (no 'MessageQueue was
    closed'), whether ``frames=`` or the end of a finite source ends the stream."""
    from rollcam.host.integrations.oaknode import EmulatedCamera

    for uri, frames in ((URI, limit), (URI + f"&frames={limit}", None)):
        seqs = []
        with dai.Pipeline(False) as pipeline:
            cam = pipeline.create(EmulatedCamera).build(uri, frames=frames)
            queue = cam.out.createOutputQueue()
            pipeline.start()
            while pipeline.isRunning():
                frame = queue.get()
                img, seq = frame.getCvFrame(), frame.getSequenceNum()
                seqs.append(seq)
        assert cam.error is None and len(seqs) == limit and seqs == sorted(seqs) and img.shape == (180, 320, 3)


def test_the_module_docstring_example_runs_as_written():
    """host/integrations/oaknode.py's example, taken from its docstring and run unchanged: every frame, then the loop
    ends."""
    import textwrap

    import rollcam.host.integrations.oaknode as oaknode

    lines = oaknode.__doc__.split("::\n\n", 1)[1].splitlines()
    end = next(i for i, line in enumerate(lines) if line and not line.startswith(" "))  # the indented block
    block = "\n".join(lines[:end])
    assert "while pipeline.isRunning():" in block and "queue.get()" in block
    ns: dict = {}
    exec(compile(textwrap.dedent(block), "host/integrations/oaknode.py docstring", "exec"), ns)
    assert ns["cam"].error is None and len(ns["images"]) == 10
    assert all(img.shape == (360, 640, 3) for img in ns["images"])


def test_a_failing_node_raises_its_error_from_get():
    from rollcam.host.integrations.oaknode import EmulatedCamera

    with dai.Pipeline(False) as pipeline:
        cam = pipeline.create(EmulatedCamera).build(URI, frames=3)
        cam.uri = "emu:nope"  # fails in the node's thread, after build() accepted the URI
        queue = cam.out.createOutputQueue()
        pipeline.start()
        with pytest.raises(SourceError, match=r"EmulatedCamera.*nope"):
            while pipeline.isRunning():
                queue.get()
