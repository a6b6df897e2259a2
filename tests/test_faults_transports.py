"""Faults on UVC (pyusb), USB/IP, HTTP MJPEG and serial reach real clients as the real failures would: the USB
status (EPIPE stall, EOVERFLOW babble, short transfers, ENODEV), missing and cut MJPEG parts, corrupted,
dropped and late serial bytes; and the client's counts match the injected ones for a fixed seed."""

from __future__ import annotations

import errno
import itertools
import shutil
import socket
import subprocess
import time

import pytest
import usb.core
from rollcam.common.faults import FaultPlan
from rollcam.emu.usbip import ImportedDevice, UrbError, USBIPServer, list_devices
from rollcam.emu.uvc import PayloadParser, Probe, UVCFunction
from rollcam.emu.uvc import constants as C
from rollcam.emu.uvc.pyusb_backend import EmulatedBackend
from uvc_fakes import FakeProducer

VS = 1
PROBE, COMMIT = C.VS_PROBE_CONTROL << 8, C.VS_COMMIT_CONTROL << 8
YUYV_64x48 = 64 * 48 * 2


def _pyusb(faults: str, transfer: str = "iso"):
    producer = FakeProducer()
    fn = UVCFunction(producer, transfer=transfer, sleep=producer.clock.sleep, faults=faults)
    backend = EmulatedBackend([fn])
    dev = usb.core.find(idVendor=0x1209, idProduct=0x0001, backend=backend)
    dev.set_configuration()
    return producer, fn, backend, dev


def _commit(dev) -> Probe:
    dev.ctrl_transfer(0x21, C.SET_CUR, PROBE, VS, Probe(bmHint=1, bFormatIndex=1, bFrameIndex=1).pack(48))
    probe = Probe.unpack(bytes(dev.ctrl_transfer(0xA1, C.GET_CUR, PROBE, VS, 48)))
    dev.ctrl_transfer(0x21, C.SET_CUR, COMMIT, VS, probe.pack(48))
    return probe


def _attempt(call, *args, error: type[Exception] = usb.core.USBError):
    """``(call(*args), None)``, or ``(None, exc)`` when it raised ``error``."""
    try:
        return call(*args), None
    except error as exc:
        return None, exc


def _usb_errno(call, *args) -> int:
    with pytest.raises(usb.core.USBError) as info:
        call(*args)
    return info.value.errno


# ------------------------------------------------------------------------------------------------ UVC / pyusb
def test_pyusb_sees_babble_as_eoverflow_and_short_packets_as_incomplete_frames():
    producer, fn, _backend, dev = _pyusb("babble=3%,short=10%,seed=4")
    probe = _commit(dev)
    dev.set_interface_altsetting(VS, 4)
    parser = PayloadParser(probe.dwClockFrequency, YUYV_64x48)
    overflows = shorts = 0
    frames = []
    while len(frames) < 30:
        data, exc = _attempt(dev.read, 0x81, 3072)
        if exc is not None:
            assert exc.errno == errno.EOVERFLOW  # what libusb reports for babble
            overflows += 1
            continue
        data = bytes(data)
        # short, yet not the frame's last payload (a cut last payload shows only as an incomplete frame)
        shorts += len(data) < 3072 and not data[1] & C.BH_EOF  # alternate setting 4: 3072-byte packets
        frames += parser.feed(data)
    st = fn.fault_stats
    assert overflows == st.babbles > 0 and 0 < shorts <= st.shorts
    assert sum(not f.complete for f in frames) == st.damaged_frames > 0  # the host sees the frames it lost
    assert [f.pts_ns for f in frames] == [producer.timestamp_ns(i) for i in range(len(frames))]


def test_pyusb_drop_is_a_missing_frame_and_error_the_err_bit():
    producer, fn, _backend, dev = _pyusb("drop=20%,error=20%,seed=9")
    probe = _commit(dev)
    dev.set_interface_altsetting(VS, 4)
    parser = PayloadParser(probe.dwClockFrequency, YUYV_64x48)
    frames = []
    while len(frames) < 20:
        frames += parser.feed(bytes(dev.read(0x81, 3072)))
    indices = [(f.pts_ns - producer.timestamp_ns(0)) // producer.interval_ns for f in frames]
    plan = FaultPlan.parse("drop=20%,error=20%,seed=9")
    assert set(range(indices[-1] + 1)) - set(indices) == {i for i in range(indices[-1] + 1) if plan.fires("drop", i)}
    assert indices[-1] + 1 - len(frames) == fn.fault_stats.dropped > 0
    assert sum(f.error for f in frames) == fn.fault_stats.errors > 0 and all(f.complete for f in frames)


def test_pyusb_bulk_stall_is_epipe_until_the_halt_is_cleared_and_control_requests_stall():
    _producer, fn, _backend, dev = _pyusb("stall=25%,seed=1", transfer="bulk")
    probe, stalls = _commit_retrying(dev)
    parser = PayloadParser(probe.dwClockFrequency, YUYV_64x48)
    frames = []
    while len(frames) < 20:
        data, exc = _attempt(dev.read, 0x81, probe.dwMaxPayloadTransferSize)
        if exc is None:
            frames += parser.feed(bytes(data))
        else:
            assert exc.errno == errno.EPIPE
            stalls += 1
            assert _usb_errno(dev.read, 0x81, probe.dwMaxPayloadTransferSize) == errno.EPIPE  # still halted
            dev.clear_halt(0x81)  # what libusb_clear_halt does after a STALL: the stream starts over
    assert stalls == fn.fault_stats.stalls > 0 and all(f.complete for f in frames)


def _commit_retrying(dev) -> tuple[Probe, int]:
    """Probe and commit, starting over after a class request STALLs (a host retries a refused request); the
    probe and the number of STALLs seen."""
    for stalls in range(50):
        probe, exc = _attempt(_commit, dev)
        if exc is None:
            return probe, stalls
        assert exc.errno == errno.EPIPE
    raise AssertionError("the commit never went through")


def test_pyusb_disconnect_is_enodev_and_the_camera_re_enumerates():
    _producer, fn, backend, dev = _pyusb("disconnect=2")
    probe = _commit(dev)
    dev.set_interface_altsetting(VS, 4)
    parser = PayloadParser(probe.dwClockFrequency, YUYV_64x48)
    frames = []
    with pytest.raises(usb.core.USBError) as info:
        while True:
            frames += parser.feed(bytes(dev.read(0x81, 3072)))
    assert info.value.errno == errno.ENODEV and len(frames) == 2
    assert _usb_errno(dev.ctrl_transfer, 0xA1, C.GET_CUR, PROBE, VS, 48) == errno.ENODEV  # the old handle is dead
    again = usb.core.find(idVendor=0x1209, idProduct=0x0001, backend=backend)
    assert again.address != dev.address and fn.fault_stats.disconnects == 1
    again.set_configuration()
    _commit(again)
    again.set_interface_altsetting(VS, 4)
    parser = PayloadParser(probe.dwClockFrequency, YUYV_64x48)
    got = []
    while len(got) < 3:  # plugged back in: it streams, and unplugs once only
        got += parser.feed(bytes(again.read(0x81, 3072)))
    assert all(f.complete for f in got)


def test_usb_backend_fixture_takes_faults(rollcam_usb_backend):
    backend = rollcam_usb_backend("imx219", scene="flat", faults="error=100%")
    dev = usb.core.find(idVendor=0x1209, idProduct=0x0001, backend=backend)
    dev.set_configuration()
    probe = _commit(dev)
    dev.set_interface_altsetting(VS, 4)
    parser = PayloadParser(probe.dwClockFrequency, probe.dwMaxVideoFrameSize)
    frames = []
    while len(frames) < 2:
        frames += parser.feed(bytes(dev.read(0x81, 3072)))
    assert all(f.error for f in frames) and backend.devices[0].function.fault_stats.errors >= 2


# ------------------------------------------------------------------------------------------------ USB/IP
@pytest.fixture
def usbip_server():
    fns = [UVCFunction(FakeProducer(), faults="babble=4%,short=10%,seed=2"),
           UVCFunction(FakeProducer(), transfer="bulk", faults="stall=20%,disconnect=6,seed=9")]
    with USBIPServer(fns, port=0) as srv:
        yield srv


def _usbip_commit(dev) -> Probe:
    dev.control(0x00, C.REQ_SET_CONFIGURATION, 1, 0, b"")
    dev.control(0x21, C.SET_CUR, PROBE, 1, Probe(bmHint=1, bFormatIndex=1, bFrameIndex=1).pack(34))
    probe = Probe.unpack(dev.control(0xA1, C.GET_CUR, PROBE, 1, 34))
    dev.control(0x21, C.SET_CUR, COMMIT, 1, probe.pack(34))
    return probe


def test_usbip_iso_packets_carry_eoverflow_and_short_lengths(usbip_server):
    fn = usbip_server.exports["1-1"].function
    with ImportedDevice(*usbip_server.address, "1-1") as dev:
        probe = _usbip_commit(dev)
        dev.control(0x01, C.REQ_SET_INTERFACE, 4, 1, b"")
        parser = PayloadParser(probe.dwClockFrequency, YUYV_64x48)
        failed = shorts = 0
        frames = []
        while len(frames) < 30:
            seq = dev.submit(1, 1, 8 * 3072, iso_lengths=(3072,) * 8)
            rep = dev._wait(seq)
            failed += sum(p.status == -errno.EOVERFLOW for p in rep.iso)
            assert rep.error_count == sum(p.status != 0 for p in rep.iso)
            pos, data, lengths = 0, [], []
            for p in rep.iso:
                chunk = rep.data[pos:pos + p.actual_length]
                pos += p.actual_length
                shorts += 0 < len(chunk) < 3072 and not chunk[1] & C.BH_EOF
                data.append(chunk)
                lengths.append(len(chunk))
            frames += parser.feed_batch(b"".join(data), lengths)
    st = fn.fault_stats
    assert failed == st.babbles > 0 and 0 < shorts <= st.shorts
    assert sum(not f.complete for f in frames) == st.damaged_frames > 0


def test_usbip_bulk_stall_and_disconnect(usbip_server):
    fn = usbip_server.exports["1-2"].function
    dev = ImportedDevice(*usbip_server.address, "1-2")
    probe = _usbip_commit(dev)
    parser = PayloadParser(probe.dwClockFrequency, YUYV_64x48)
    stalls, frames = 0, []
    with pytest.raises(ConnectionError, match="closed"):  # the connection ends unanswered, as on an unplug
        while True:
            data, exc = _attempt(dev.bulk_read, 0x81, probe.dwMaxPayloadTransferSize, error=UrbError)
            if exc is None:
                frames += parser.feed(data)
            else:
                assert exc.status == -errno.EPIPE  # a STALL, as the stub driver reports it
                stalls += 1
                dev.control(0x02, C.REQ_CLEAR_FEATURE, C.FEATURE_ENDPOINT_HALT, 0x81, b"")
    dev.close()
    assert stalls == fn.fault_stats.stalls > 0 and fn.fault_stats.disconnects == 1
    assert sum(f.complete for f in frames) >= 1
    deadline = time.monotonic() + 5
    while fn.plug.disconnected and time.monotonic() < deadline:  # the server resets the device once the peer is gone
        time.sleep(0.02)
    assert [d.busid for d in list_devices(*usbip_server.address)] == ["1-1", "1-2"]
    with ImportedDevice(*usbip_server.address, "1-2") as again:  # plugged back in: it imports and answers
        assert again.control(0x80, C.REQ_GET_DESCRIPTOR, 0x0100, 0, 18) == fn.descriptors.device


@pytest.mark.skipif(shutil.which("usbip") is None, reason="Linux usbip tool not installed (apt-get install usbip)")
def test_linux_usbip_lists_the_camera_again_after_its_disconnect(usbip_server):
    fn = usbip_server.exports["1-2"].function
    with ImportedDevice(*usbip_server.address, "1-2") as dev:
        probe = _usbip_commit(dev)
        with pytest.raises(ConnectionError):
            for _ in range(200):
                if _attempt(dev.bulk_read, 0x81, probe.dwMaxPayloadTransferSize, error=UrbError)[1]:
                    dev.control(0x02, C.REQ_CLEAR_FEATURE, C.FEATURE_ENDPOINT_HALT, 0x81, b"")
    assert fn.fault_stats.disconnects == 1
    host, port = usbip_server.address
    out = subprocess.run(["usbip", "--tcp-port", str(port), "list", "-r", host], capture_output=True, text=True,
                         timeout=30)
    assert out.returncode == 0 and "1-2:" in out.stdout, out.stderr


# ------------------------------------------------------------------------------------------------ HTTP
def _read_parts(url: str, timeout_s: float = 10.0, limit: int = 40):
    """A raw multipart reader: [(headers, body bytes, complete)] until EOF or ``limit`` parts, and the arrival
    time of each part."""
    host, port = url.split("//")[1].split("/")[0].split(":")
    sock = socket.create_connection((host, int(port)), timeout=timeout_s)
    sock.sendall(b"GET /stream.mjpg HTTP/1.1\r\nHost: x\r\n\r\n")
    f = sock.makefile("rb")
    while f.readline() not in (b"\r\n", b""):
        pass  # response head
    parts, times = [], []
    try:
        while len(parts) < limit:
            line = f.readline()
            if not line:
                break
            if not line.startswith(b"--"):
                continue
            headers = {}
            while (h := f.readline()) not in (b"\r\n", b""):
                k, _, v = h.decode().partition(":")
                headers[k.strip()] = v.strip()
            n = int(headers["Content-Length"])
            body = f.read(n)
            parts.append((headers, body, len(body) == n))
            times.append(time.monotonic())
            if len(body) < n:
                break
    finally:
        sock.close()
    return parts, times


def test_http_drops_are_sequence_gaps_and_a_cut_ends_the_part_short(rollcam_http_camera):
    srv = rollcam_http_camera("imx219", scene={"scene": "flat"}, size=(640, 480), faults="drop=20%,cut=8%,seed=5")
    parts, _ = _read_parts(srv.url)
    seqs = [int(h["X-Sequence"]) for h, _, _ in parts]
    assert not parts[-1][2] and all(c for _, _, c in parts[:-1])  # the cut part is short, then end of file
    plan = FaultPlan.parse("drop=20%,cut=8%,seed=5")
    assert plan.fires("cut", seqs[-1]) and not any(plan.fires("cut", s) for s in seqs[:-1])
    assert not any(plan.fires("drop", s) for s in seqs)
    st = srv.fault_stats
    assert st.cuts >= 1 and st.dropped >= sum(plan.fires("drop", s) for s in range(seqs[0], seqs[-1]))
    parts2, _ = _read_parts(srv.url, limit=2)  # the camera is still there for a new connection
    assert len(parts2) >= 1


def test_http_delay_holds_the_stream_and_disconnect_ends_it(rollcam_http_camera):
    srv = rollcam_http_camera("imx219", scene={"scene": "flat"}, size=(640, 480),
                              faults="delay=30%,delay_ms=400,disconnect=8,seed=1")
    parts, times = _read_parts(srv.url)
    assert all(c for _, _, c in parts) and len(parts) < 40  # the stream ended, at a part boundary
    assert len(parts) + srv.slots.dropped_total == 8  # after N parts (those a slow reader skipped counted)
    gaps = [b - a for a, b in itertools.pairwise(times)]
    assert srv.fault_stats.delayed >= 1 and max(gaps) >= 0.35
    assert srv.fault_stats.disconnects == 1


def test_opencv_reads_the_stream_until_the_cut(rollcam_http_camera):
    cv2 = pytest.importorskip("cv2")
    srv = rollcam_http_camera("imx219", scene={"scene": "flat"}, size=(640, 480), faults="disconnect=5")
    cap = cv2.VideoCapture(srv.url, cv2.CAP_FFMPEG)
    assert cap.isOpened()
    n = 0
    while n < 20 and cap.read()[0]:
        n += 1
    cap.release()
    assert 1 <= n <= 5  # the stream ends with the injected disconnect; OpenCV's reader sees the end


# ------------------------------------------------------------------------------------------------ serial
def _ask(port, line: bytes, wait_s: float = 0.5) -> bytes:
    port.reset_input_buffer()
    port.write(line)
    end, out = time.monotonic() + wait_s, b""
    while time.monotonic() < end:
        out += port.read(256)
        if out.endswith(b"\n"):
            break
    return out


def test_serial_bytes_are_dropped_and_corrupted_as_counted(rollcam_serial_port):
    serial = pytest.importorskip("serial")
    clean = rollcam_serial_port("imx219", scene="flat")
    with serial.Serial(clean.path, timeout=0.05) as port:
        want = _ask(port, b"*IDN?\n")
    faulty = rollcam_serial_port("imx219", scene="flat", faults="corrupt=3%,seed=8")
    with serial.Serial(faulty.path, timeout=0.05) as port:
        replies = [_ask(port, b"*IDN?\n", 0.3) for _ in range(10)]
    flipped = sum(bin(a ^ b).count("1") for r in replies for a, b in zip(r, want, strict=False))
    assert all(len(r) == len(want) for r in replies)
    assert flipped == faulty.fault_stats.corrupted > 0  # one bit flipped per corrupted byte
    lossy = rollcam_serial_port("imx219", scene="flat", faults="drop=5%,seed=8")
    with serial.Serial(lossy.path, timeout=0.05) as port:
        replies = [_ask(port, b"*IDN?\n", 0.3) for _ in range(10)]
    assert sum(len(want) - len(r) for r in replies) == lossy.fault_stats.dropped > 0


def test_serial_delayed_reply_times_out_then_arrives(rollcam_serial_port):
    serial = pytest.importorskip("serial")
    port_srv = rollcam_serial_port("imx219", scene="flat", faults="delay=100%,delay_ms=600")
    with serial.Serial(port_srv.path, timeout=0.2) as port:
        port.write(b"*IDN?\n")
        assert port.readline() == b""  # pyserial's timeout: nothing within 0.2 s
        port.timeout = 2
        assert port.readline().startswith(b"rollcam,")
    assert port_srv.fault_stats.delayed == 1
