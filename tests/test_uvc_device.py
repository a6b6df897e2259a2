"""The UVC function through ordinary pyusb code: enumeration, probe/commit, controls, STALLs, streaming, pacing."""

from __future__ import annotations

import errno
import itertools

import numpy as np
import pytest
import usb.core
import usb.util
from helpers import FakeClock
from rollcam.emu.uvc import PayloadParser, Probe, Setup, Stall, UVCFunction
from rollcam.emu.uvc import constants as C
from rollcam.emu.uvc.convert import decode
from rollcam.emu.uvc.pyusb_backend import EmulatedBackend
from uvc_fakes import FakeProducer

VS = 1
PROBE, COMMIT = C.VS_PROBE_CONTROL << 8, C.VS_COMMIT_CONTROL << 8


def _open(transfer="iso", **kw):
    producer = FakeProducer(**kw)
    fn = UVCFunction(producer, transfer=transfer, sleep=producer.clock.sleep)
    dev = usb.core.find(idVendor=0x1209, idProduct=0x0001, backend=EmulatedBackend([fn]))
    assert dev is not None
    dev.set_configuration()
    return producer, fn, dev


def _commit(dev, fmt=1, frame=1, interval=333333, length=48):
    dev.ctrl_transfer(0x21, C.SET_CUR, PROBE, VS, Probe(bmHint=1, bFormatIndex=fmt, bFrameIndex=frame,
                                                          dwFrameInterval=interval).pack(length))
    probe = Probe.unpack(bytes(dev.ctrl_transfer(0xA1, C.GET_CUR, PROBE, VS, length)))
    dev.ctrl_transfer(0x21, C.SET_CUR, COMMIT, VS, probe.pack(length))
    return probe


def _realtime_iso_stream():
    """A real-time function on a fake clock (its sleeps move it), committed and streaming isochronously."""
    clock = FakeClock()
    producer = FakeProducer(clock=clock)
    fn = UVCFunction(producer, realtime=True, sleep=clock.sleep, render_ahead=False)
    dev = usb.core.find(idVendor=0x1209, backend=EmulatedBackend([fn]))
    dev.set_configuration()
    probe = _commit(dev)
    dev.set_interface_altsetting(VS, 4)
    return clock, producer, fn, dev, probe


def _error_code(dev) -> int:
    return dev.ctrl_transfer(0xA1, C.GET_CUR, C.VC_REQUEST_ERROR_CODE_CONTROL << 8, 0, 1)[0]


def test_pyusb_enumerates_and_reads_strings_and_descriptors():
    _, fn, dev = _open()
    assert (dev.idVendor, dev.idProduct, dev.bDeviceClass) == (0x1209, 0x0001, 0xEF)
    assert dev.manufacturer == "rollcam" and dev.serial_number == "0001"
    cfg = dev.get_active_configuration()
    alts = [(i.bInterfaceNumber, i.bAlternateSetting, [e.wMaxPacketSize for e in i]) for i in cfg]
    assert alts == [(0, 0, []), (1, 0, []), (1, 1, [0x200]), (1, 2, [0x400]), (1, 3, [0xC00]), (1, 4, [0x1400])]
    assert bytes(cfg.extra_descriptors)[1] == C.DT_INTERFACE_ASSOCIATION
    vc = usb.util.find_descriptor(cfg, bInterfaceNumber=0)
    assert bytes(vc.extra_descriptors)[2] == C.VC_HEADER
    assert bytes(dev.ctrl_transfer(0x80, 6, 0x0200, 0, 4096)) == fn.descriptors.configuration


@pytest.mark.parametrize("length", C.PROBE_LENGTHS)
def test_probe_negotiation_in_every_form(length):
    _, fn, dev = _open()
    get = lambda req: Probe.unpack(bytes(dev.ctrl_transfer(0xA1, req, PROBE, VS, length)))  # noqa: E731
    assert dev.ctrl_transfer(0xA1, C.GET_LEN, PROBE, VS, 2).tobytes() == (48).to_bytes(2, "little")
    assert dev.ctrl_transfer(0xA1, C.GET_INFO, PROBE, VS, 1)[0] == C.INFO_GET | C.INFO_SET
    assert get(C.GET_MIN).dwFrameInterval == 333333 and get(C.GET_MAX).dwFrameInterval == 666667
    assert get(C.GET_DEF).bFormatIndex == 1
    dev.ctrl_transfer(0x21, C.SET_CUR, PROBE, VS, Probe(bFormatIndex=2, bFrameIndex=2,
                                                          dwFrameInterval=600000).pack(length))
    cur = get(C.GET_CUR)
    assert (cur.bFormatIndex, cur.bFrameIndex, cur.dwFrameInterval) == (2, 2, 666667)  # nearest offered
    assert cur.dwMaxVideoFrameSize == 32 * 24 * 3 // 2
    if length >= 34:
        assert cur.dwClockFrequency == fn.clock_hz
    dev.ctrl_transfer(0x21, C.SET_CUR, COMMIT, VS, cur.pack(length))
    c = fn.controls.committed
    assert (c.fourcc, c.width, c.height, c.interval_ns) == ("NV12", 32, 24, 66_666_667)
    assert Probe.unpack(bytes(dev.ctrl_transfer(0xA1, C.GET_CUR, COMMIT, VS, length))).bFormatIndex == 2


def test_camera_controls_map_to_the_producer():
    producer, _, dev = _open()
    exp = C.CT_EXPOSURE_TIME_ABSOLUTE_CONTROL << 8
    ct = C.TERMINAL_CAMERA << 8
    assert int.from_bytes(dev.ctrl_transfer(0xA1, C.GET_CUR, exp, ct, 4), "little") == 100
    assert int.from_bytes(dev.ctrl_transfer(0xA1, C.GET_MAX, exp, ct, 4), "little") == 300
    dev.ctrl_transfer(0x21, C.SET_CUR, exp, ct, (42).to_bytes(4, "little"))
    assert producer.controls["exposure_ns"] == 4_200_000
    gain, pu = C.PU_GAIN_CONTROL << 8, C.UNIT_PROCESSING << 8
    dev.ctrl_transfer(0x21, C.SET_CUR, gain, pu, (400).to_bytes(2, "little"))
    assert producer.controls["gain"] == 400
    assert int.from_bytes(dev.ctrl_transfer(0xA1, C.GET_DEF, gain, pu, 2), "little") == 100
    assert dev.ctrl_transfer(0xA1, C.GET_RES, C.CT_AE_MODE_CONTROL << 8, ct, 1)[0] == 0x01


BAD_REQUESTS = [  # (bmRequestType, bRequest, wValue, wIndex, data_or_length, expected error code)
    (0xA1, C.GET_CUR, PROBE, 0x0509, 48, C.ERR_INVALID_UNIT),
    (0xA1, C.GET_CUR, 0x7700, C.TERMINAL_CAMERA << 8, 4, C.ERR_INVALID_CONTROL),
    (0xA1, 0x99, PROBE, VS, 48, C.ERR_INVALID_REQUEST),
    (0x21, C.SET_CUR, PROBE, VS, bytes(30), C.ERR_INVALID_VALUE),
    (0x21, C.SET_CUR, PROBE, VS, Probe(bFormatIndex=9, bFrameIndex=1).pack(), C.ERR_OUT_OF_RANGE),
    (0x21, C.SET_CUR, COMMIT, VS, Probe(bFormatIndex=1, bFrameIndex=1, dwFrameInterval=5).pack(), C.ERR_INVALID_VALUE),
    (0x21, C.SET_CUR, C.CT_EXPOSURE_TIME_ABSOLUTE_CONTROL << 8, C.TERMINAL_CAMERA << 8, (10**6).to_bytes(4, "little"),
     C.ERR_OUT_OF_RANGE),
    (0xA1, C.GET_CUR, C.PU_GAIN_CONTROL << 8, C.UNIT_PROCESSING << 8, 4, C.ERR_INVALID_REQUEST),
    (0xA1, C.GET_MIN, C.CT_AE_MODE_CONTROL << 8, C.TERMINAL_CAMERA << 8, 1, C.ERR_INVALID_REQUEST),
    (0x21, C.SET_CUR, C.VC_REQUEST_ERROR_CODE_CONTROL << 8, 0, b"\x00", C.ERR_INVALID_REQUEST),
    (0xA1, C.GET_MIN, COMMIT, VS, 48, C.ERR_INVALID_REQUEST),
]


@pytest.mark.parametrize("request_", BAD_REQUESTS)
def test_malformed_requests_stall_and_set_the_error_code(request_):
    _, fn, dev = _open()
    *args, code = request_
    with pytest.raises(usb.core.USBError) as err:
        dev.ctrl_transfer(*args)
    assert err.value.errno == errno.EPIPE
    assert _error_code(dev) == code
    _commit(dev)  # the device still works
    assert _error_code(dev) == C.ERR_NONE
    assert fn.stats.stalls == 1


def test_standard_request_errors_stall():
    _, _fn, dev = _open()
    for args in [(0x00, C.REQ_SET_CONFIGURATION, 7, 0, b""), (0x01, C.REQ_SET_INTERFACE, 9, 1, b""),
                 (0x80, C.REQ_GET_DESCRIPTOR, 0x0300 | 9, 0, 255), (0x80, C.REQ_GET_DESCRIPTOR, 0x2200, 0, 9)]:
        with pytest.raises(usb.core.USBError):
            dev.ctrl_transfer(*args)
    with pytest.raises(usb.core.USBError):  # alternate setting before commit
        dev.set_interface_altsetting(VS, 1)
    with pytest.raises(Stall):
        UVCFunction(FakeProducer()).control(Setup(0xA1, C.GET_CUR, PROBE, VS, 48))  # not configured yet


@pytest.mark.parametrize(("transfer", "fmt"), [("iso", 1), ("iso", 2), ("bulk", 1), ("bulk", 3)])
def test_pyusb_streams_frames_through_the_backend(transfer, fmt):
    producer, fn, dev = _open(transfer)
    probe = _commit(dev, fmt=fmt)
    fourcc = fn.formats[fmt - 1].fourcc
    if transfer == "iso":
        alt = next(a for a, n in enumerate((512, 1024, 2048, 3072), 1) if n >= probe.dwMaxPayloadTransferSize)
        dev.set_interface_altsetting(VS, alt)
        size = (512, 1024, 2048, 3072)[alt - 1]
    else:
        size = probe.dwMaxPayloadTransferSize
    sizes = {"YUYV": 64 * 48 * 2, "NV12": 64 * 48 * 3 // 2, "MJPG": None}
    parser = PayloadParser(probe.dwClockFrequency, sizes[fourcc])
    frames = []
    while len(frames) < 3:
        frames += parser.feed(bytes(dev.read(0x81, size)))
    for i, f in enumerate(frames):
        assert f.complete and not f.error
        assert f.pts_ns == producer.timestamp_ns(i)
        img = decode(f.data, fourcc, 64, 48)
        assert abs(float(np.median(img)) - ((i * 37) % 200 + 20)) <= 3
    if transfer == "bulk":
        dev.clear_halt(0x81)  # stops a bulk stream
        assert not fn.streaming
    else:
        dev.set_interface_altsetting(VS, 0)
        assert not fn.streaming
    with pytest.raises(usb.core.USBError):
        dev.ctrl_transfer(0x21, C.SET_CUR, COMMIT, VS, Probe(bFormatIndex=1, bFrameIndex=1,
                                                               dwFrameInterval=1).pack())


def _bulk_payloads(dev, transfer: int, max_payload: int, n: int) -> tuple[list[bytes], int]:
    """Payloads reassembled from bulk transfers of ``transfer`` bytes as uvcvideo does: a payload ends with a
    short transfer (a zero-length one included) or when it reaches the negotiated maximum. Also returns how
    many zero-length transfers came."""
    payloads, current, zlps = [], b"", 0
    while len(payloads) < n:
        got = bytes(dev.read(0x81, transfer))
        zlps += not got
        current += got
        if current and (len(got) < transfer or len(current) >= max_payload):
            payloads.append(current)
            current = b""
    return payloads, zlps


@pytest.mark.parametrize(("transfer", "zlps"), [(1024, 0), (3078, 3)])
def test_a_bulk_payload_longer_than_the_transfer_goes_on_in_the_next_transfers(transfer, zlps):
    """uvcvideo's bulk URBs (16 KiB) are smaller than the negotiated payload (512 KiB): each payload spans
    transfers, ended by a short packet, or by a zero-length packet when it ends on a transfer's last byte."""
    producer, _fn, dev = _open("bulk")
    probe = _commit(dev)
    payloads, got_zlps = _bulk_payloads(dev, transfer, probe.dwMaxPayloadTransferSize, 3)
    assert [len(p) for p in payloads] == [64 * 48 * 2 + 12] * 3 and got_zlps == zlps  # 6,156 = 2 x 3,078
    parser = PayloadParser(probe.dwClockFrequency, 64 * 48 * 2)
    frames = [f for p in payloads for f in parser.feed(p)]
    assert len(frames) == 3
    for i, f in enumerate(frames):
        assert f.complete and not f.error and f.pts_ns == producer.timestamp_ns(i)
        assert abs(float(np.median(decode(f.data, "YUYV", 64, 48))) - ((i * 37) % 200 + 20)) <= 3


def test_commit_while_streaming_is_refused():
    _, _fn, dev = _open()
    probe = _commit(dev)
    dev.set_interface_altsetting(VS, 4)
    with pytest.raises(usb.core.USBError):
        dev.ctrl_transfer(0x21, C.SET_CUR, COMMIT, VS, probe.pack())
    assert _error_code(dev) == C.ERR_WRONG_STATE


def test_realtime_slow_host_drops_frames_and_counts_them():
    clock, producer, fn, dev, probe = _realtime_iso_stream()
    parser = PayloadParser(probe.dwClockFrequency, 64 * 48 * 2)
    assert bytes(dev.read(0x81, 3072)) == b""  # nothing read out yet: a zero-length packet
    clock.t += 40_000_000  # frame 0 is due
    got = []
    while not got:
        got += parser.feed(bytes(dev.read(0x81, 3072)))
    clock.t += 10 * 33_333_333  # the host stalls for ten frame periods
    while len(got) < 2:
        got += parser.feed(bytes(dev.read(0x81, 3072)))
    assert fn.stats.frames_dropped == 9
    assert producer.rendered == [0, 10]  # skipped frames are never rendered: memory and time stay bounded
    assert got[1].pts_ns - got[0].pts_ns == 10 * 33_333_333
    fn.mark_errors(1)
    while len(got) < 3:
        clock.t += 1_000_000
        got += parser.feed(bytes(dev.read(0x81, 3072)))
    assert got[2].error


def test_bulk_read_times_out_when_no_frame_is_due():
    clock = FakeClock()
    producer = FakeProducer(clock=clock)
    fn = UVCFunction(producer, transfer="bulk", realtime=True, sleep=lambda s: None,
                     render_ahead=False)
    dev = usb.core.find(idVendor=0x1209, backend=EmulatedBackend([fn]))
    dev.set_configuration()
    _commit(dev)
    with pytest.raises(usb.core.USBTimeoutError):
        dev.read(0x81, fn.controls.committed.payload_size, timeout=5)
    clock.t += 10**9
    assert len(dev.read(0x81, 100)) == 100  # smaller than the payload: its first bytes, the rest follows


def test_reset_mid_frame_counts_an_aborted_frame():
    _, fn, dev = _open()
    _commit(dev)
    dev.set_interface_altsetting(VS, 1)
    dev.read(0x81, 512)
    dev.reset()
    assert fn.stats.frames_aborted == 1 and not fn.streaming and fn.configuration == 0


def test_render_ahead_offers_the_newest_completed_frame_and_counts_the_rest():
    """Real clock: frames every 10 ms, a host that reads every ~25 ms gets the newest frame each time."""
    import time

    t0 = time.monotonic_ns()
    producer = FakeProducer(intervals_ns=(10_000_000,), clock=lambda: time.monotonic_ns() - t0)
    fn = UVCFunction(producer, transfer="bulk", realtime=True)
    dev = usb.core.find(idVendor=0x1209, backend=EmulatedBackend([fn]))
    dev.set_configuration()
    probe = _commit(dev, interval=100_000)
    parser = PayloadParser(probe.dwClockFrequency, 64 * 48 * 2)
    got = []
    while len(got) < 6:
        got += parser.feed(bytes(dev.read(0x81, probe.dwMaxPayloadTransferSize, timeout=2000)))
        if got and len(got) % 2:
            time.sleep(0.025)
    indices = [(f.pts_ns - producer.t0) // 10_000_000 for f in got]
    assert indices == sorted(set(indices)) and all(f.complete for f in got)
    for f, i in zip(got, indices, strict=True):
        assert f.pts_ns == producer.timestamp_ns(i)
        assert abs(float(np.median(decode(f.data, "YUYV", 64, 48))) - ((i * 37) % 200 + 20)) <= 3
    skipped = sum(b - a - 1 for a, b in itertools.pairwise(indices))
    assert skipped > 0 and fn.stats.frames_dropped >= skipped
    dev.clear_halt(0x81)  # stops the stream and its renderer thread
    assert not fn.streaming and fn.stream._ahead is None


def test_a_replaced_frames_insensor_results_ride_on_the_frame_that_replaced_it():
    """A host slower than the frames: the slot's untaken frame is replaced, and the in-sensor results it
    carried come with the frame that replaced it, so every frame rendered is reported once, in order."""
    import dataclasses
    import time
    import types

    from rollcam.emu.uvc.ahead import RenderAhead

    class Carrying(FakeProducer):
        def frame(self, index):
            return dataclasses.replace(super().frame(index), insensor=(f"r{index}",))

    t0 = time.monotonic_ns()
    producer = Carrying(intervals_ns=(10_000_000,), clock=lambda: time.monotonic_ns() - t0)
    producer.configure(64, 48, 10_000_000)
    stats = types.SimpleNamespace(frames_dropped=0)
    ahead = RenderAhead(producer, lambda f: f.data.reshape(-1), stats)
    taken = []
    try:
        while len(taken) < 4:
            got = ahead.take()
            if isinstance(got, int):
                time.sleep(got / 1e9)
                continue
            taken.append(got)
            time.sleep(0.035)  # three and a half frames
    finally:
        ahead.stop()
    last = taken[-1][0]
    seen = [r for _, f, _ in taken for r in f.insensor]
    assert stats.frames_dropped > 0 and len(seen) > len(taken)
    assert seen == [f"r{i}" for i in producer.rendered if i <= last]


def test_realtime_isochronous_endpoint_keeps_the_bus_pace():
    """A high-speed bus serves an isochronous endpoint once per service interval (125 us at bInterval 1):
    however fast the host asks, packets (full or empty) arrive at no more than 8,000 a second of device time,
    and frames still get through. Fake clock: the function's sleeps move it."""
    clock, _producer, fn, dev, probe = _realtime_iso_stream()
    assert fn.bus.interval_ns == 125_000
    parser = PayloadParser(probe.dwClockFrequency, 64 * 48 * 2)
    t0, packets, frames = clock.t, 0, []
    while clock.t - t0 < 200_000_000:  # 0.2 s of device time, URBs of 32 packets back to back
        data, lengths, _status = fn.read_packets(0x81, 32, 3072)
        packets += len(lengths)
        frames += parser.feed_batch(data, lengths)
    for _ in range(40):  # one packet a read, as pyusb reads an isochronous endpoint
        dev.read(0x81, 3072)
        packets += 1
    elapsed_s = (clock.t - t0) / 1e9
    assert packets / elapsed_s <= 8000 * 1.001
    assert packets / elapsed_s >= 8000 * 0.99  # a host that keeps asking gets every interval
    assert len(frames) >= 5 and all(f.complete for f in frames)


def test_service_interval_follows_binterval_and_a_late_host_loses_intervals():
    from rollcam.emu.uvc.stream import BusSchedule, service_interval_ns

    ep = bytes((7, C.DT_ENDPOINT, 0x81, 0x05, 0x00, 0x14, 4))  # bInterval 4: every 8 microframes
    assert service_interval_ns(ep) == 8 * 125_000
    bus = BusSchedule(125_000)
    assert bus.book(8, 0) == 1_000_000  # back to back: 8 intervals
    assert bus.book(1, 500_000) == 1_125_000  # asked early: waits for the next free interval
    assert bus.book(2, 5_000_000) == 5_250_000  # asked late: the intervals in between went by empty
