"""USB/IP over loopback: list, import and stream with a client; refusals, malformed peers, unlink, disconnects."""

from __future__ import annotations

import contextlib
import errno
import re
import shlex
import shutil
import socket
import struct
import subprocess
import sys
import threading
import time

import pytest
from helpers import FakeClock, wait_for
from interrupts import interrupt
from rollcam.emu.usbip import ImportedDevice, UrbError, USBIPServer, list_devices
from rollcam.emu.usbip import protocol as P
from rollcam.emu.uvc import PayloadParser, Probe, UVCFunction
from rollcam.emu.uvc import constants as C
from uvc_fakes import FakeProducer

PROBE, COMMIT = C.VS_PROBE_CONTROL << 8, C.VS_COMMIT_CONTROL << 8


@pytest.fixture
def server():
    fns = [UVCFunction(FakeProducer()), UVCFunction(FakeProducer(), transfer="bulk")]
    with USBIPServer(fns, port=0) as srv:
        yield srv


def _commit(dev, fmt=1, frame=1):
    dev.control(0x00, C.REQ_SET_CONFIGURATION, 1, 0, b"")
    dev.control(0x21, C.SET_CUR, PROBE, 1, Probe(bmHint=1, bFormatIndex=fmt, bFrameIndex=frame).pack(34))
    probe = Probe.unpack(dev.control(0xA1, C.GET_CUR, PROBE, 1, 34))
    dev.control(0x21, C.SET_CUR, COMMIT, 1, probe.pack(34))
    return probe


def test_several_clients_list_the_devices_at_once(server):
    results, errors = [], []

    def run():
        try:
            results.append(list_devices(*server.address))
        except Exception as exc:  # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=run) for _ in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors and len(results) == 6
    devs = results[0]
    assert [d.busid for d in devs] == ["1-1", "1-2"]
    d = devs[0]
    assert (d.idVendor, d.idProduct, d.speed, d.bDeviceClass) == (0x1209, 0x0001, 3, 0xEF)
    assert d.interfaces == ((C.CC_VIDEO, C.SC_VIDEOCONTROL, 1), (C.CC_VIDEO, C.SC_VIDEOSTREAMING, 1))
    assert all(r == devs for r in results)


def test_import_and_stream_isochronous(server):
    with ImportedDevice(*server.address, "1-1") as dev:
        assert dev.control(0x80, C.REQ_GET_DESCRIPTOR, 0x0100, 0, 18) == \
            server.exports["1-1"].function.descriptors.device
        probe = _commit(dev, fmt=2)
        dev.control(0x01, C.REQ_SET_INTERFACE, 4, 1, b"")
        parser = PayloadParser(probe.dwClockFrequency, 64 * 48 * 3 // 2)
        frames = []
        while len(frames) < 3:
            frames += parser.feed_many(dev.iso_read(0x81, 8, 3072))
        producer = server.exports["1-1"].function.producer
        assert [f.pts_ns for f in frames] == [producer.timestamp_ns(i) for i in range(len(frames))]
        assert all(f.complete and not f.error for f in frames)
        with pytest.raises(UrbError) as err:  # a STALL travels back as -EPIPE
            dev.control(0xA1, C.GET_CUR, PROBE, 0x0509, 48)
        assert err.value.status == -errno.EPIPE


def test_import_and_stream_bulk(server):
    with ImportedDevice(*server.address, "1-2") as dev:
        probe = _commit(dev)
        parser = PayloadParser(probe.dwClockFrequency, 64 * 48 * 2)
        frames = []
        while len(frames) < 2:
            frames += parser.feed(dev.bulk_read(0x81, probe.dwMaxPayloadTransferSize))
        assert all(f.complete for f in frames)


def test_one_importer_at_a_time_and_release_on_disconnect(server):
    fn = server.exports["1-1"].function
    dev = ImportedDevice(*server.address, "1-1")
    _commit(dev)
    dev.control(0x01, C.REQ_SET_INTERFACE, 1, 1, b"")
    dev.iso_read(0x81, 2, 512)  # part of a frame, then the client vanishes
    with pytest.raises(Exception, match=r"refused.*device busy"):
        ImportedDevice(*server.address, "1-1")
    with pytest.raises(Exception, match=r"refused.*device not found"):
        ImportedDevice(*server.address, "9-9")
    dev.close()
    wait_for(lambda: server.exports["1-1"].owner is None, 5.0, "camera 1-1 freed", every_s=0.01)
    assert fn.stats.frames_aborted == 1 and not fn.streaming
    with ImportedDevice(*server.address, "1-1") as again:
        assert again.control(0x80, C.REQ_GET_CONFIGURATION, 0, 0, 1) == b"\x00"  # reset for the next importer
    assert server.stats.refused == 2


def _raw(server, payload: bytes) -> bytes:
    with socket.create_connection(server.address, timeout=5) as s:
        s.sendall(payload)
        s.shutdown(socket.SHUT_WR)
        out = b""
        try:
            while chunk := s.recv(65536):
                out += chunk
        except ConnectionResetError:
            pass  # the server closed with our unread bytes in its buffer
        return out


def test_malformed_peers_lose_their_connection_only(server):
    assert _raw(server, b"\x02\x00\x80\x05\x00\x00\x00\x00") == b""  # wrong version
    assert _raw(server, P.op_header(0x8123)) == P.op_header(0x0123, P.ST_ERROR)  # unknown operation
    assert _raw(server, b"\x01") == b""  # truncated
    bad_urb = P.req_import("1-2") + struct.pack(">IIIII", 9, 1, 0x10002, 0, 0) + bytes(28)
    reply = _raw(server, bad_urb)
    assert reply[:8] == P.op_header(P.OP_REP_IMPORT) and len(reply) == 8 + 312  # imported, then dropped
    huge = P.Submit(1, 0x10002, P.DIR_OUT, 0, 0, 1 << 30, 0, P.NON_ISO, 0, bytes(8)).pack()
    assert len(_raw(server, P.req_import("1-2") + huge)) == 8 + 312
    wait_for(lambda: server.stats.malformed == 4 and server.exports["1-2"].owner is None, 5.0,
             "4 malformed requests counted and camera 1-2 freed", every_s=0.01)
    assert len(list_devices(*server.address)) == 2  # still serving


def test_unlink_cancels_a_queued_urb():
    clock, gate = FakeClock(), threading.Event()
    fn = UVCFunction(FakeProducer(clock=clock), transfer="bulk", realtime=True, sleep=gate.wait,
                     render_ahead=False)
    with USBIPServer([fn], port=0) as srv, ImportedDevice(*srv.address, "1-1") as dev:
        probe = _commit(dev)
        size = probe.dwMaxPayloadTransferSize
        first = dev.submit(1, P.DIR_IN, size)  # blocks: no frame is due on the manual clock
        second = dev.submit(1, P.DIR_IN, size)
        time.sleep(0.1)
        # control requests are answered while the stream endpoint waits
        assert Probe.unpack(dev.control(0xA1, C.GET_CUR, COMMIT, 1, 34)).bFormatIndex == 1
        unlink = dev.unlink(second)
        rep = dev.reply()
        assert isinstance(rep, P.RetUnlink) and rep.seqnum == unlink and rep.status == -errno.ECONNRESET
        clock.t += 10**9
        rep = dev.reply()
        assert isinstance(rep, P.RetSubmit) and rep.seqnum == first and rep.status == 0 and rep.actual_length > 12
        late = dev.unlink(first)
        rep = dev.reply()
        assert isinstance(rep, P.RetUnlink) and rep.seqnum == late and rep.status == 0
        assert srv.stats.unlinked == 1


def test_unlink_of_a_running_urb_answers_with_the_ret_unlink_alone():
    """Linux's stub driver: a URB already running ends early and is answered by its RET_UNLINK; no RET_SUBMIT
    follows (vhci-hcd gave the URB back at the unlink and drops a device that answers it again)."""
    clock = FakeClock()

    def sleep(seconds: float) -> None:  # device time passes at once, real time a little
        clock.sleep(seconds)
        time.sleep(0.005)

    fn = UVCFunction(FakeProducer(clock=clock, intervals_ns=(10**11,)), transfer="bulk", realtime=True,
                     sleep=sleep, render_ahead=False)
    with USBIPServer([fn], port=0) as srv, ImportedDevice(*srv.address, "1-1") as dev:
        size = _commit(dev).dwMaxPayloadTransferSize
        running = dev.submit(1, P.DIR_IN, size)  # its worker waits for a frame due in 100 s of device time
        # a bulk stream starts at its first read: the URB is running
        wait_for(lambda: fn.streaming, 5.0, "the bulk stream running", every_s=0.01)
        unlink = dev.unlink(running)
        rep = dev.reply()
        assert isinstance(rep, P.RetUnlink) and rep.seqnum == unlink and rep.status == -errno.ECONNRESET
        clock.t += 10**12
        after = dev.submit(1, P.DIR_IN, size)
        rep = dev.reply()
        assert isinstance(rep, P.RetSubmit) and rep.seqnum == after and rep.status == 0  # nothing for `running`
        assert srv.stats.unlinked == 1


def test_an_unlink_that_comes_before_its_urb_cancels_it_when_it_arrives():
    """vhci-hcd sends its unlink list after its submit list, so a URB submitted and unlinked in between is
    unlinked before it is submitted. Answering that unlink 0 (nothing pending) and running the URB later, as
    Linux's stub does, gives vhci-hcd a reply to a URB it has given back, and it drops the device."""
    clock = FakeClock()
    fn = UVCFunction(FakeProducer(clock=clock), transfer="bulk", realtime=True, sleep=clock.sleep,
                     render_ahead=False)
    with USBIPServer([fn], port=0) as srv, ImportedDevice(*srv.address, "1-1") as dev:
        size = _commit(dev).dwMaxPayloadTransferSize  # seqnums 1-4
        unlink = dev.unlink(6)
        assert unlink == 5 and dev.submit(1, P.DIR_IN, size) == 6
        rep = dev.reply()
        assert isinstance(rep, P.RetUnlink) and rep.seqnum == unlink and rep.status == -errno.ECONNRESET
        clock.t += 10**9
        after = dev.submit(1, P.DIR_IN, size)
        rep = dev.reply()
        assert isinstance(rep, P.RetSubmit) and rep.seqnum == after and rep.status == 0  # nothing for 6
        assert srv.stats.unlinked == 1
        old = dev.unlink(3)  # an unlink of a URB answered long ago is still answered 0 at once
        rep = dev.reply()
        assert isinstance(rep, P.RetUnlink) and rep.seqnum == old and rep.status == 0


def test_a_flooding_client_does_not_block_the_others(server):
    with socket.create_connection(server.address) as s:
        s.sendall(P.req_import("1-2"))
        s.recv(8 + 312, socket.MSG_WAITALL)
        setup = struct.pack("<BBHHH", 0x80, C.REQ_GET_DESCRIPTOR, 0x0200, 0, 4096)
        urb = b"".join(P.Submit(i, 0x10002, P.DIR_IN, 0, 0, 4096, 0, 0, 0, setup).pack() for i in range(1, 2000))
        s.setblocking(False)
        with contextlib.suppress(BlockingIOError):
            s.sendall(urb)  # never reads a reply: the server's queue and socket buffers fill, then it pushes back
        assert len(list_devices(*server.address)) == 2


def test_an_independent_usbip_client_lists_imports_and_streams(server):
    """The PyPI ``usbip`` package's host side (another implementation of the protocol) against this server."""
    usbip = pytest.importorskip("usbip")
    from usbip import protocol as UP

    host, port = server.address
    with socket.create_connection((host, port)) as s:
        listed = UP.client_devlist(s)
    assert [(d["busid"], d["idVendor"], d["bNumInterfaces"]) for d in listed] == [("1-1", 0x1209, 2),
                                                                                 ("1-2", 0x1209, 2)]
    handle = usbip.attach(host, "1-1", port=port, vid=0x1209, pid=0x0001)
    try:
        assert handle.device_descriptor.bDeviceClass == 0xEF
        handle.control(0x21, C.SET_CUR, PROBE, 1, Probe(bFormatIndex=1, bFrameIndex=1).pack())
        probe = Probe.unpack(bytes(handle.control(0xA1, C.GET_CUR, PROBE, 1, 48)))
        handle.control(0x21, C.SET_CUR, COMMIT, 1, probe.pack())
        handle.control(0x01, C.REQ_SET_INTERFACE, 4, 1, b"")
        parser = PayloadParser(probe.dwClockFrequency, 64 * 48 * 2)
        frames = []
        while len(frames) < 3:
            frames += parser.feed_many(handle.iso_in(0x81, 3072, 8))
        assert [f.pts_ns for f in frames[:3]] == [0, 33_333_333, 66_666_666]
    finally:
        handle.close()


def test_refusals_carry_the_statuses_linux_usbip_decodes(server):
    """usbip_common.h: ST_DEV_BUSY 2 for a device someone else imported, ST_NODEV 4 for an unknown busid."""
    assert (P.ST_OK, P.ST_NA, P.ST_DEV_BUSY, P.ST_DEV_ERR, P.ST_NODEV, P.ST_ERROR) == (0, 1, 2, 3, 4, 5)
    assert _raw(server, P.req_import("9-9")) == P.op_header(P.OP_REP_IMPORT, P.ST_NODEV)
    with ImportedDevice(*server.address, "1-2"):
        assert _raw(server, P.req_import("1-2")) == P.op_header(P.OP_REP_IMPORT, P.ST_DEV_BUSY)
    assert _raw(server, P.op_header(0x8123)) == P.op_header(0x0123, P.ST_ERROR)


def test_usbip_hints_put_the_port_before_the_subcommand():
    from rollcam.emu.usbip import usbip_commands

    assert usbip_commands("127.0.0.1", 3241, "1-1") == (
        "usbip --tcp-port 3241 list -r 127.0.0.1", "sudo usbip --tcp-port 3241 attach -r 127.0.0.1 -b 1-1")


USBIP_TOOL = shutil.which("usbip")


@pytest.mark.skipif(USBIP_TOOL is None, reason="Linux usbip tool not installed (apt-get install usbip)")
def test_linux_usbip_lists_the_emulated_camera_from_the_emulate_hint():
    """``rollcam emulate --usbip`` prints a ``usbip ... list`` line; run it as printed with the real tool (no
    kernel module needed to list) and find the camera's busid and ids in its output."""
    cmd = [sys.executable, "-m", "rollcam.host.cli", "emulate", "imx219", "--size", "640x480", "--scene", "flat",
           "--usbip", "127.0.0.1:0", "--duration", "120"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        lines = []
        while not any("USB/IP:" in x for x in lines):
            line = proc.stdout.readline()
            assert line, "".join(lines)
            lines.append(line)
        hint = next(x for x in lines if "USB/IP:" in x)
        list_cmd = re.search(r"\((usbip [^;]*list[^;]*);", hint).group(1)
        out = subprocess.run(shlex.split(list_cmd), capture_output=True, text=True, timeout=30)
        assert out.returncode == 0, out.stderr
        assert re.search(r"1-1: .*\(1209:0001\)", out.stdout), out.stdout
    finally:
        interrupt(proc, timeout_s=30)


@pytest.mark.skipif(USBIP_TOOL is None, reason="Linux usbip tool not installed (apt-get install usbip)")
def test_linux_usbip_list_shows_every_busid(server):
    host, port = server.address
    out = subprocess.run([USBIP_TOOL, "--tcp-port", str(port), "list", "-r", host], capture_output=True, text=True,
                         timeout=30)
    assert out.returncode == 0, out.stderr
    assert "1-1:" in out.stdout and "1-2:" in out.stdout and "1209:0001" in out.stdout
    assert server.stats.devlists == 1
