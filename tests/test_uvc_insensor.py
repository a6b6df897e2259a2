"""In-sensor results over UVC: a metadata item after the standard payload header fields, packed by the camera,
parsed back by the host (the pyusb backend and the USB/IP protocol), on the device clock of the PTS."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from rollcam.emu.uvc.metadata import MAX_DETECTIONS, RCIS_ITEM_ID, decode, encode, to_result
from rollcam.emu.uvc.payload import HEADER_LEN, PayloadPacker, PayloadParser, ns_to_ticks
from rollcam.host import open_camera
from rollcam.sim.insensor import InSensorResult

pytest.importorskip("usb")


def result(n: int, seq: int = 7) -> InSensorResult:
    rng = np.random.default_rng(n)
    x0 = rng.uniform(0, 600, n)
    y0 = rng.uniform(0, 400, n)
    boxes = np.stack([x0, y0, x0 + 20, y0 + 50], axis=1)
    return InSensorResult(seq=seq, boxes=boxes, scores=rng.uniform(0.2, 1, n), classes=np.zeros(n),
                          timestamp_ns=5_000_000_000, line_time_ns=18_904, readout="top_to_bottom",
                          exposure_ns=10_000_000, input_ns=5_019_000_000, done_ns=5_019_036_392, input_size=(640, 480))


def test_item_round_trip_and_truncation():
    r = result(30)
    item = encode((r,), frame_seq=8, clock_hz=1_000_000_000)
    assert len(item) <= 255 - HEADER_LEN
    other = struct.pack("<II", 0x80000002, 12) + b"abcd"  # another vendor's item first: skipped
    got = decode(other + item, 1_000_000_000)
    assert got is not None and got["truncated"] and len(got["detections"]) == MAX_DETECTIONS == 21
    best = np.argsort(-r.scores, kind="stable")[:MAX_DETECTIONS]
    assert np.allclose([d["box"] for d in got["detections"]], np.round(r.boxes[best]), atol=0.5)
    assert np.allclose([d["score"] for d in got["detections"]], r.scores[best], atol=0.5 / 255 + 1e-9)
    pts = ns_to_ticks(5_033_333_333, 1_000_000_000) & 0xFFFFFFFF  # the carrying frame's PTS
    back = to_result(got, pts, 5_033_333_333, 1_000_000_000, seq=8)
    assert (back.seq, back.timestamp_ns, back.input_ns, back.done_ns) == (7, r.timestamp_ns, r.input_ns, r.done_ns)
    assert encode((), 8, 1_000_000_000) == b"" and decode(b"", 1_000_000_000) is None
    assert struct.unpack_from("<I", item)[0] == RCIS_ITEM_ID


@pytest.mark.parametrize("frame_bytes", [0, 100, 3000, 3072 * 5 + 17])
def test_the_first_payload_carries_the_item_and_the_frame_is_intact(frame_bytes):
    data = np.random.default_rng(frame_bytes).integers(0, 256, frame_bytes, dtype=np.uint8)
    item = encode((result(3),), 8, 1_000_000_000)
    packer = PayloadPacker(3072, 1_000_000_000)
    batch = packer.pack(data, 5_033_333_333, 5_040_000_000, extra=item)
    assert batch.nbytes <= packer.buffer_size(frame_bytes, len(item))
    assert batch[0][0] == HEADER_LEN + len(item) and all(p[0] == HEADER_LEN for p in list(batch)[1:])
    one_by_one = PayloadParser(1_000_000_000, frame_bytes).feed_many(list(batch))  # per payload
    batched = PayloadParser(1_000_000_000, frame_bytes).feed_batch(batch.buffer, batch.lengths)  # numpy path
    for frames in (one_by_one, batched):
        assert len(frames) == 1 and frames[0].complete and frames[0].data == data.tobytes()
        assert frames[0].extra == item


def _check_against_device(frames, producer):
    carried = 0
    for f in frames:
        truth = producer.frame(f.sequence)
        assert len(f.insensor) == len(truth.insensor)
        for got, want in zip(f.insensor, truth.insensor, strict=True):
            # Device-clock times exact (1 GHz PTS clock); the source frame before this one.
            assert (got.seq, got.timestamp_ns, got.input_ns, got.done_ns) == \
                (want.seq, want.timestamp_ns, want.input_ns, want.done_ns)
            assert got.seq < f.sequence and got.done_ns <= f.timestamp_ns + (want.input_ns - want.timestamp_ns)
            n = min(len(want), MAX_DETECTIONS)
            order = np.argsort(-want.scores, kind="stable")[:n]
            assert len(got) == n
            assert np.allclose(got.boxes, np.clip(np.round(want.boxes[order]), 0, 65535), atol=0.5)
            assert np.allclose(got.scores, want.scores[order], atol=0.5 / 255 + 1e-6)
            carried += n
    assert carried > 0


def test_uvc_source_reads_the_results_through_pyusb():
    uri = "uvc:1209:0001?backend=emu&sensor=imx219&size=640x480&insensor=personnet-raw&frames=4"
    with open_camera(uri) as src:
        frames = list(src)
        producer = src.function.producer
    assert [f.sequence for f in frames] == [0, 1, 2, 3] and frames[0].insensor == ()
    _check_against_device(frames, producer)


def test_uvc_results_over_usbip():
    from rollcam.emu.usbip import USBIPServer
    from rollcam.emu.uvc import FirmwareProducer, UVCFunction
    from rollcam.firmware.camera import FirmwareCamera
    from rollcam.firmware.spec import CameraSpec

    spec = CameraSpec.from_options("imx219", {"size": "640x480", "insensor": "personnet-raw"})
    fn = UVCFunction(FirmwareProducer(FirmwareCamera(spec)), transfer="bulk")
    with USBIPServer([fn], port=0) as srv:
        host, port = srv.address
        with open_camera(f"uvc:1209:0001?backend=usbip&usbip={host}:{port}&busid=1-1&frames=3&size=640x480") as src:
            frames = list(src)
    _check_against_device(frames, fn.producer)
