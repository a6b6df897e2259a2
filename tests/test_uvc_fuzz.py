"""Fuzzing the parsers a peer can feed: UVC control requests, UVC payloads, USB/IP messages (hypothesis).

Each test counts the inputs it tried and prints the count (``pytest -s`` shows them).
"""

from __future__ import annotations

import contextlib
import io
import socket

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rollcam.common.errors import ProtocolError
from rollcam.emu.usbip import USBIPServer, list_devices
from rollcam.emu.usbip import protocol as P
from rollcam.emu.uvc import PayloadPacker, PayloadParser, Probe, Setup, Stall, UVCFunction
from rollcam.emu.uvc import constants as C
from uvc_fakes import FakeProducer

FUZZ = settings(max_examples=1000, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


def _report(name: str, n: int, minimum: int) -> None:
    print(f"\nfuzz {name}: {n} inputs")
    assert n >= minimum


# ------------------------------------------------------------------------------ UVC control requests
def _configured() -> UVCFunction:
    fn = UVCFunction(FakeProducer())
    fn.control(Setup(0x00, C.REQ_SET_CONFIGURATION, 1, 0, 0))
    return fn


requests = st.tuples(
    st.sampled_from([0x21, 0xA1, 0x00, 0x80, 0x01, 0x81, 0x02, 0x22, 0xA2, 0x41, 0xC1]) | st.integers(0, 255),
    st.sampled_from([*sorted(C.REQUEST_NAMES), 6, 9, 11, 1]) | st.integers(0, 255),
    st.sampled_from([0x0100, 0x0200, 0x0400, 0x0600, 0x0200 | 0]) | st.integers(0, 0xFFFF),
    st.sampled_from([0x0001, 0x0100, 0x0200, 0x0000, 0x0300, 0x0201]) | st.integers(0, 0xFFFF),
    st.sampled_from([1, 2, 4, 26, 34, 48]) | st.integers(0, 300),
    st.binary(max_size=64) | st.sampled_from([Probe(bFormatIndex=1, bFrameIndex=1).pack(n) for n in (26, 34, 48)]),
)


def test_fuzz_uvc_control_requests():
    fn = _configured()
    count = 0

    @FUZZ
    @given(st.lists(requests, min_size=1, max_size=6))
    def run(batch):
        nonlocal count
        for rt, req, value, index, length, data in batch:
            count += 1
            setup = Setup(rt, req, value, index, length)
            try:
                out = fn.control(setup, b"" if setup.is_in else data)
            except Stall as exc:
                assert 0 <= exc.code <= 0xFF
                continue
            assert isinstance(out, bytes) and len(out) <= length
        # whatever came before, the device still configures and negotiates
        fn.control(Setup(0x00, C.REQ_SET_CONFIGURATION, 1, 0, 0))
        fn.set_interface(1, 0)
        fn.control(Setup(0x21, C.SET_CUR, 0x0100, 1, 48), Probe(bFormatIndex=1, bFrameIndex=1).pack())
        assert len(fn.control(Setup(0xA1, C.GET_CUR, 0x0100, 1, 48))) == 48

    run()
    _report("UVC control requests", count, 1000)


# ------------------------------------------------------------------------------------- UVC payloads
def _valid_payloads(n_frames: int, size: int) -> list[bytes]:
    packer = PayloadPacker(64, 10**9)
    return [bytes(p) for i in range(n_frames) for p in packer.pack(bytes([i]) * size, i * 1000, i * 1000)]


@st.composite
def damaged_streams(draw):
    payloads = _valid_payloads(draw(st.integers(1, 4)), draw(st.integers(0, 300)))
    for _ in range(draw(st.integers(0, 6))):
        i = draw(st.integers(0, max(len(payloads) - 1, 0)))
        action = draw(st.sampled_from(["drop", "dup", "flip", "truncate", "junk", "swap"]))
        if not payloads:
            break
        if action == "drop":
            payloads.pop(i)
        elif action == "dup":
            payloads.insert(i, payloads[i])
        elif action == "flip":
            p = bytearray(payloads[i])
            if p:
                p[draw(st.integers(0, len(p) - 1))] ^= 1 << draw(st.integers(0, 7))
            payloads[i] = bytes(p)
        elif action == "truncate":
            payloads[i] = payloads[i][: draw(st.integers(0, len(payloads[i])))]
        elif action == "junk":
            payloads.insert(i, draw(st.binary(max_size=40)))
        else:
            j = draw(st.integers(0, len(payloads) - 1))
            payloads[i], payloads[j] = payloads[j], payloads[i]
    return payloads


def test_fuzz_payload_parser():
    count = 0

    @FUZZ
    @given(damaged_streams() | st.lists(st.binary(max_size=80), max_size=20))
    def run(payloads):
        nonlocal count
        count += 1
        parser = PayloadParser(10**9, frame_size=300)
        frames = parser.feed_many(payloads)
        s = parser.stats
        assert s.payloads == len(payloads) and s.frames == len(frames)
        assert s.complete <= s.frames and s.bad_headers + s.empty <= s.payloads
        assert sum(len(f.data) for f in frames) <= sum(len(p) for p in payloads)
        for f in frames:
            assert f.complete == (len(f.data) == 300)

    run()
    _report("UVC payload streams", count, 1000)


# -------------------------------------------------------------------------------------- USB/IP codec
def _recv_from(data: bytes):
    buf = io.BytesIO(data)

    def recv(n: int) -> bytes:
        out = buf.read(n)
        if len(out) < n:
            raise ConnectionError("end of stream")
        return out
    return recv


submits = st.builds(
    P.Submit, st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1), st.integers(0, 1), st.integers(0, 15),
    st.integers(0, 2**32 - 1), st.integers(0, 4096), st.integers(-10, 10), st.sampled_from([0, P.NON_ISO, 1, 4]),
    st.integers(0, 2**32 - 1), st.binary(min_size=8, max_size=8))


def test_fuzz_usbip_decoder():
    count = 0

    @FUZZ
    @given(st.binary(max_size=200) | submits.map(lambda s: s.pack()).flatmap(
        lambda raw: st.tuples(st.just(raw), st.integers(0, len(raw)), st.binary(max_size=8)).map(
            lambda t: t[0][: t[1]] + t[2] + t[0][t[1] + len(t[2]):])))
    def run(data):
        nonlocal count
        count += 1
        recv = _recv_from(data)
        try:
            while True:
                cmd = P.read_command(recv)
                assert 0 <= cmd.seqnum < 2**32  # a u32 on the wire
                if isinstance(cmd, P.Submit):
                    assert len(cmd.data) <= P.MAX_TRANSFER and len(cmd.iso) <= P.MAX_ISO_PACKETS
        except (ProtocolError, ConnectionError):
            pass
        for with_intf in (True, False):
            with contextlib.suppress(ConnectionError):
                P.ExportedDevice.read(_recv_from(data), with_intf)

    run()
    _report("USB/IP messages", count, 1000)


def test_fuzz_usbip_server_survives_random_peers():
    count = 0
    with USBIPServer([UVCFunction(FakeProducer())], port=0) as srv:

        @settings(max_examples=60, deadline=None, derandomize=True)
        @given(st.binary(max_size=120).map(lambda b: P.op_header(P.OP_REQ_IMPORT) + b"1-1".ljust(32, b"\0") + b)
               | st.binary(max_size=120))
        def run(data):
            nonlocal count
            count += 1
            with socket.create_connection(srv.address, timeout=5) as s, contextlib.suppress(OSError):
                # The server may close first (and reset): that is its answer to garbage.
                s.sendall(data)
                s.shutdown(socket.SHUT_WR)
                while s.recv(65536):
                    pass

        run()
        assert [d.busid for d in list_devices(*srv.address)] == ["1-1"]
    _report("USB/IP server connections", count, 60)


@pytest.mark.parametrize("length", [0, 7, 9])
def test_probe_decoder_rejects_wrong_lengths(length):
    with pytest.raises(ProtocolError):
        Probe.unpack(bytes(length))


def test_fuzz_batch_parser_matches_payload_by_payload():
    count = 0

    @FUZZ
    @given(damaged_streams() | st.lists(st.binary(max_size=80), max_size=20), st.integers(1, 5))
    def run(payloads, n_batches):
        nonlocal count
        count += 1
        one, batched = PayloadParser(10**9, frame_size=300), PayloadParser(10**9, frame_size=300)
        expected = one.feed_many(payloads)
        got = []
        step = -(-len(payloads) // n_batches) if payloads else 1
        for i in range(0, max(len(payloads), 1), step):
            part = payloads[i:i + step]
            got += batched.feed_batch(b"".join(part), [len(p) for p in part])
        key = lambda f: (f.data, f.fid, f.pts_ns, f.scr, f.error, f.complete, f.payloads)  # noqa: E731
        assert [key(f) for f in got] == [key(f) for f in expected]
        assert batched.stats == one.stats

    run()
    _report("batch vs per-payload parsing", count, 1000)
