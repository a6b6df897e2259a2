"""USB/IP server under attack (loopback, small configured limits): descriptor exhaustion, idle and stalled
peers, importers that never send or go idle, failed isochronous URBs, URB floods; the real ``usbip`` tool
keeps listing the device throughout."""

from __future__ import annotations

import errno
import json
import shutil
import socket
import struct
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest
from helpers import FakeClock, wait_for
from rollcam.common.errors import ConfigError, DeviceError
from rollcam.emu.usbip import ImportedDevice, UrbError, USBIPServer, list_devices
from rollcam.emu.usbip import protocol as P
from rollcam.emu.usbip.server import ServerLimits
from rollcam.emu.usbip.session import failed
from rollcam.emu.uvc import Probe, UVCFunction
from rollcam.emu.uvc import constants as C
from uvc_fakes import FakeProducer

USBIP_TOOL = shutil.which("usbip")
TESTS = Path(__file__).parent


def _linux_lists(address) -> None:
    """The real ``usbip`` tool lists busid 1-1 (skipped where it is not installed)."""
    if USBIP_TOOL is None:
        return
    host, port = address
    out = subprocess.run([USBIP_TOOL, "--tcp-port", str(port), "list", "-r", host], capture_output=True,
                         text=True, timeout=20)
    assert out.returncode == 0 and "1-1:" in out.stdout, out.stderr


def _conn_threads() -> int:
    return sum(t.name == "usbip-conn" and t.is_alive() for t in threading.enumerate())


def test_limits_are_validated():
    with pytest.raises(ConfigError, match="max_connections"):
        ServerLimits(max_connections=0)
    with pytest.raises(ConfigError, match="idle_timeout_s"):
        ServerLimits(idle_timeout_s=float("nan"))


def test_stalled_peers_are_bounded_and_timed_out_while_real_clients_are_served():
    limits = ServerLimits(max_connections=4, handshake_timeout_s=0.5)
    with USBIPServer([UVCFunction(FakeProducer())], port=0, limits=limits) as srv:
        stalled = []
        try:
            for _ in range(12):  # three bytes of an operation header, then nothing
                s = socket.create_connection(srv.address, timeout=5)
                s.sendall(b"\x01\x11\x80")
                stalled.append(s)
                assert srv.connection_count <= 4
            wait_for(lambda: _conn_threads() <= 4, 5.0, "at most 4 connection threads")
            assert len(list_devices(*srv.address)) == 1  # served although every slot was held
            _linux_lists(srv.address)
            assert srv.stats.shed >= 8
            wait_for(lambda: srv.connection_count == 0, 5.0, "every connection closed")  # the rest time out
            assert srv.stats.timed_out >= 1
        finally:
            for s in stalled:
                s.close()


def test_an_importer_that_never_sends_loses_the_device():
    limits = ServerLimits(import_timeout_s=0.3)
    with USBIPServer([UVCFunction(FakeProducer())], port=0, limits=limits) as srv, \
            socket.create_connection(srv.address, timeout=5) as squatter:
        squatter.sendall(P.req_import("1-1"))
        assert len(squatter.recv(8 + 312, socket.MSG_WAITALL)) == 8 + 312
        with pytest.raises(Exception, match="device busy"):
            ImportedDevice(*srv.address, "1-1")
        _linux_lists(srv.address)
        wait_for(lambda: srv.exports["1-1"].owner is None, 5.0, "camera 1-1 freed")
        assert srv.stats.timed_out == 1
        with ImportedDevice(*srv.address, "1-1") as dev:
            assert dev.control(0x80, C.REQ_GET_CONFIGURATION, 0, 0, 1) == b"\x00"


def test_an_idle_importer_gives_the_device_up_to_a_peer_only_once_idle():
    limits = ServerLimits(idle_timeout_s=0.4)
    with USBIPServer([UVCFunction(FakeProducer())], port=0, limits=limits) as srv:
        first = ImportedDevice(*srv.address, "1-1")
        try:
            first.control(0x80, C.REQ_GET_CONFIGURATION, 0, 0, 1)
            with pytest.raises(Exception, match="device busy"):  # active: kept
                ImportedDevice(*srv.address, "1-1")
            time.sleep(0.5)
            with ImportedDevice(*srv.address, "1-1") as second:
                assert second.control(0x80, C.REQ_GET_CONFIGURATION, 0, 0, 1) == b"\x00"
            assert srv.stats.evicted == 1
            with pytest.raises((OSError, ConnectionError)):
                first.control(0x80, C.REQ_GET_CONFIGURATION, 0, 0, 1)
        finally:
            first.close()


def test_a_failed_iso_urb_carries_one_descriptor_per_packet():
    urb = P.Submit(7, 0x10001, P.DIR_IN, 1, 0, 1024, 0, 4, 1, bytes(8), iso=tuple(
        P.IsoPacket(256 * i, 256) for i in range(4)))
    rep = failed(urb, -errno.EPIPE)
    assert (rep.number_of_packets, rep.error_count, rep.actual_length) == (4, 4, 0)
    assert [(p.offset, p.length, p.actual_length, p.status) for p in rep.iso] == \
        [(256 * i, 256, 0, -errno.EPIPE) for i in range(4)]
    assert len(rep.pack()) == P.URB_HEADER + 4 * 16  # what vhci-hcd reads: header, then N descriptors


def test_a_failed_iso_urb_keeps_the_connection_in_step():
    """An iso read before the stream starts STALLs; the reply must carry its packet descriptors, or the client
    reads the next reply as descriptors and hangs."""
    with USBIPServer([UVCFunction(FakeProducer())], port=0) as srv, \
            ImportedDevice(*srv.address, "1-1", timeout_s=5) as dev:
        seq = dev.submit(1, P.DIR_IN, 4 * 512, iso_lengths=(512,) * 4)
        rep = dev.reply()
        assert rep.seqnum == seq and rep.status == -errno.EPIPE
        assert rep.error_count == 4 and [p.status for p in rep.iso] == [-errno.EPIPE] * 4
        with pytest.raises(UrbError):
            dev.iso_read(0x81, 8, 512)
        assert dev.control(0x80, C.REQ_GET_CONFIGURATION, 0, 0, 1) == b"\x00"  # still in step


def test_an_importer_cannot_queue_more_than_its_byte_budget():
    clock, gate = FakeClock(), threading.Event()
    fn = UVCFunction(FakeProducer(clock=clock), transfer="bulk", realtime=True, sleep=gate.wait,
                     render_ahead=False)
    limits = ServerLimits(max_urb_bytes=64 * 1024)
    with USBIPServer([fn], port=0, limits=limits) as srv, ImportedDevice(*srv.address, "1-1") as dev:
        dev.control(0x00, C.REQ_SET_CONFIGURATION, 1, 0, b"")
        probe_sel = C.VS_PROBE_CONTROL << 8
        dev.control(0x21, C.SET_CUR, probe_sel, 1, Probe(bmHint=1, bFormatIndex=1, bFrameIndex=1).pack(34))
        probe = Probe.unpack(dev.control(0xA1, C.GET_CUR, probe_sel, 1, 34))
        dev.control(0x21, C.SET_CUR, C.VS_COMMIT_CONTROL << 8, 1, probe.pack(34))
        dev._sock.setblocking(False)
        for _ in range(40):  # 40 x 16 KiB bulk reads that wait for a frame that is never due
            urb = P.Submit(0, dev.info.devid, P.DIR_IN, 1, 0, 16 * 1024, 0, P.NON_ISO, 0, bytes(8))
            try:
                dev._sock.sendall(urb.pack())
            except BlockingIOError:
                break
        session = srv.exports["1-1"].owner.session
        wait_for(lambda: session.reserved_bytes == 64 * 1024, 5.0, "64 KiB reserved")
        time.sleep(0.2)
        assert session.peak_reserved_bytes == 64 * 1024 and sum(map(len, session.queues)) == 3
        assert len(list_devices(*srv.address)) == 1
        _linux_lists(srv.address)


_EXHAUST = textwrap.dedent("""
    import json, logging, os, resource, sys
    sys.path.insert(0, sys.argv[1])
    from rollcam.emu.usbip import USBIPServer
    from rollcam.emu.usbip.server import ServerLimits
    from rollcam.emu.uvc import Probe, UVCFunction
    from uvc_fakes import FakeProducer

    records = []
    class Keep(logging.Handler):
        def emit(self, record):
            records.append(record.getMessage())
    logging.getLogger("rollcam.usbip").addHandler(Keep())
    srv = USBIPServer([UVCFunction(FakeProducer())], port=0, limits=ServerLimits(handshake_timeout_s=60))
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (len(os.listdir("/proc/self/fd")) + 16, hard))
    fill = []
    while True:  # every descriptor this process may have, so accept() gets EMFILE
        try:
            fill.append(os.open(os.devnull, os.O_RDONLY))
        except OSError:
            break
    print(srv.address[1], flush=True)
    sys.stdin.readline()
    for fd in fill:
        os.close(fd)
    print("freed", flush=True)
    sys.stdin.readline()
    print(json.dumps({"stats": srv.stats.to_json(), "log": records, "alive": srv._accept.alive}), flush=True)
    srv.close()
""")


def test_descriptor_exhaustion_is_survived_and_logged_once():
    """With every descriptor taken, accept() fails (EMFILE) for as long as that lasts: the server logs it once,
    backs off, and serves the connections waiting in its backlog once descriptors are free again."""
    proc = subprocess.Popen([sys.executable, "-c", _EXHAUST, str(TESTS)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    try:
        port = int(proc.stdout.readline())
        # a blocked accept() reserves its descriptor before it waits, so it may hold one from before the limit:
        # a stalled peer takes that one, and the client after it must wait for accept() to succeed again
        stalled = socket.create_connection(("127.0.0.1", port), timeout=10)
        stalled.sendall(b"\x01\x11\x80")
        waiting = socket.create_connection(("127.0.0.1", port), timeout=10)
        waiting.sendall(P.op_header(P.OP_REQ_DEVLIST))
        time.sleep(1.0)
        proc.stdin.write("free\n")
        proc.stdin.flush()
        assert proc.stdout.readline().strip() == "freed"
        reply = waiting.recv(12, socket.MSG_WAITALL)  # answered once descriptors are free again
        assert reply[:8] == P.op_header(P.OP_REP_DEVLIST) and struct.unpack(">I", reply[8:])[0] == 1
        waiting.close()
        stalled.close()
        assert len(list_devices("127.0.0.1", port)) == 1
        _linux_lists(("127.0.0.1", port))
        proc.stdin.write("report\n")
        proc.stdin.flush()
        report = json.loads(proc.stdout.readline())
    finally:
        proc.stdin.close()
        proc.wait(timeout=20)
    log, errors = report["log"], report["stats"]["accept_errors"]
    assert report["alive"] and errors >= 3, report
    assert "Too many open files" in log[0] and "accepting again" in log[-1], log
    assert len(log) == 2, log  # once per episode, not once per retry


def test_a_connection_thread_that_breaks_is_joined_and_its_error_raised_on_close():
    """What a peer does ends its connection quietly; a fault of the server's own (here the device's reset after
    the importer left) is kept by the connection's worker and raised by ``close()``, not lost on stderr."""

    class BrokenReset(UVCFunction):
        def reset(self) -> None:
            super().reset()
            raise RuntimeError("reset broke")

    srv = USBIPServer([BrokenReset(FakeProducer())], port=0)
    try:
        with ImportedDevice(*srv.address, "1-1") as dev:
            assert dev.control(0x80, C.REQ_GET_DESCRIPTOR, 0x0100, 0, 18)[:2] == bytes([18, 1])
        wait_for(lambda: srv.connection_count == 0 and srv.exports["1-1"].owner is None, 5.0,
                 "the connection closed and camera 1-1 given back")
        with ImportedDevice(*srv.address, "1-1") as dev:  # still served
            assert dev.control(0x80, C.REQ_GET_DESCRIPTOR, 0x0100, 0, 18)[:2] == bytes([18, 1])
    finally:
        with pytest.raises(DeviceError, match=r"usbip-conn failed: RuntimeError\('reset broke'\)"):
            srv.close()
