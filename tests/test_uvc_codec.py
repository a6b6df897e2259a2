"""UVC codecs as pure functions: descriptors, probe/commit forms, payload headers, packing and parsing."""

from __future__ import annotations

import numpy as np
import pytest
from rollcam.common.errors import ProtocolError
from rollcam.emu.uvc import constants as C
from rollcam.emu.uvc.convert import WIRE_FORMATS, decode, encode, wire_layout
from rollcam.emu.uvc.descriptors import (
    FrameSize,
    StreamFormat,
    build_descriptors,
    decode_max_packet,
    encode_max_packet,
    parse_streaming,
    split_descriptors,
)
from rollcam.emu.uvc.payload import (
    PayloadPacker,
    PayloadParser,
    pack_header,
    parse_header,
    ticks_to_ns,
)
from rollcam.emu.uvc.probe import Probe

FORMATS = (StreamFormat("YUYV", (FrameSize(640, 480, (333333, 666667), 666667), FrameSize(320, 240, (333333,)))),
           StreamFormat("NV12", (FrameSize(640, 480, (333333,)),)),
           StreamFormat("MJPG", (FrameSize(640, 480, (166667, 333333)),)))


def test_descriptor_set_round_trips_formats_sizes_intervals_and_alt_settings():
    d = build_descriptors(FORMATS, clock_hz=48_000_000)
    assert d.device[0] == 18 and d.device[1] == C.DT_DEVICE and d.device[4:7] == bytes((0xEF, 2, 1))
    assert int.from_bytes(d.configuration[2:4], "little") == len(d.configuration)
    parts = split_descriptors(d.configuration)
    assert [p[1] for p in parts[:3]] == [C.DT_CONFIGURATION, C.DT_INTERFACE_ASSOCIATION, C.DT_INTERFACE]
    subtypes = [p[2] for p in parts if p[1] == C.CS_INTERFACE]
    for needed in (C.VC_HEADER, C.VC_INPUT_TERMINAL, C.VC_PROCESSING_UNIT, C.VC_OUTPUT_TERMINAL, C.VS_INPUT_HEADER,
                   C.VS_FORMAT_UNCOMPRESSED, C.VS_FRAME_UNCOMPRESSED, C.VS_FORMAT_MJPEG, C.VS_FRAME_MJPEG):
        assert needed in subtypes
    info = parse_streaming(d.configuration)
    assert info.formats == FORMATS
    assert info.formats[0].frames[0].default_100ns == 666667 and info.formats[0].frames[1].default_100ns == 333333
    assert info.transfer == "iso" and info.endpoint == 0x81 and info.interface == 1
    assert info.alt_packet_sizes == {1: 512, 2: 1024, 3: 2048, 4: 3072}
    assert info.clock_hz == 48_000_000
    vc_header = next(p for p in parts if p[1] == C.CS_INTERFACE and p[2] == C.VC_HEADER)
    assert int.from_bytes(vc_header[3:5], "little") == 0x0150  # bcdUVC 1.5
    bulk = parse_streaming(build_descriptors(FORMATS, transfer="bulk").configuration)
    assert bulk.transfer == "bulk" and bulk.alt_packet_sizes == {0: 512}


def test_max_packet_encoding_uses_high_bandwidth_bits():
    assert [encode_max_packet(n) for n in (512, 1024, 2048, 3072)] == [0x200, 0x400, 0xC00, 0x1400]
    assert all(decode_max_packet(encode_max_packet(n)) == n for n in (8, 512, 1024, 2048, 3072))
    with pytest.raises(ProtocolError):
        encode_max_packet(4096)


def test_descriptor_errors():
    with pytest.raises(ProtocolError):
        build_descriptors(FORMATS, transfer="interrupt")
    with pytest.raises(ProtocolError):
        build_descriptors((StreamFormat("YUYV", ()),))
    with pytest.raises(ProtocolError):
        split_descriptors(b"\x09\x02\x00")


@pytest.mark.parametrize("length", C.PROBE_LENGTHS)
def test_probe_forms(length):
    full = Probe(bmHint=1, bFormatIndex=2, bFrameIndex=3, dwFrameInterval=333333, dwMaxVideoFrameSize=614400,
                 dwMaxPayloadTransferSize=3072, dwClockFrequency=10**9, bmFramingInfo=3, bPreferedVersion=1,
                 bUsage=1, bBitDepthLuma=8, bmLayoutPerStream=0x1122334455667788)
    raw = full.pack(length)
    assert len(raw) == length
    back = Probe.unpack(raw)
    assert back.dwMaxPayloadTransferSize == 3072 and back.bFrameIndex == 3
    assert back.dwClockFrequency == (10**9 if length >= 34 else 0)
    assert back.bmLayoutPerStream == (0x1122334455667788 if length == 48 else 0)
    with pytest.raises(ProtocolError):
        Probe.unpack(raw[:-1])


def test_header_codec():
    h = pack_header(1, eof=True, pts=0x1_0000_0005, scr=(7, 0x900))
    assert len(h) == 12 and h[1] == C.BH_FID | C.BH_EOF | C.BH_PTS | C.BH_SCR | C.BH_EOH
    p = parse_header(h + b"data")
    assert (p.fid, p.pts, p.scr) == (1, 5, (7, 0x100))
    assert parse_header(pack_header(0)).length == 2
    for bad in (b"", b"\x0c", b"\x02\x04abcd", b"\x10\x00"):
        with pytest.raises(ProtocolError):
            parse_header(bad)


def _frame(n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, n, dtype=np.uint8)


@pytest.mark.parametrize("payload_size", [64, 3072, 1 << 20])
def test_pack_then_parse_recovers_bytes_fid_and_exact_pts(payload_size):
    packer = PayloadPacker(payload_size, 10**9)
    parser = PayloadParser(10**9, 5000)
    frames = [_frame(5000, i) for i in range(4)]
    times = [123, 2_000_000_456, 4_000_000_789, 6_000_000_123]  # past 2**32 ticks, steps < 2**31
    out = []
    for f, t in zip(frames, times, strict=True):
        batch = packer.pack(f, t, t + 5)
        assert sum(batch.lengths) == batch.nbytes == 5000 + 12 * len(batch)
        assert all(n <= payload_size for n in batch.lengths)
        out += parser.feed_many(batch)
    assert [o.data for o in out] == [f.tobytes() for f in frames]
    assert [o.fid for o in out] == [0, 1, 0, 1]
    assert [o.pts_ns for o in out] == times  # 1 GHz clock: exact, and unwrapped past 2**32 ticks
    assert all(o.complete and not o.error for o in out)
    assert parser.stats.complete == 4


def test_pts_on_a_48_mhz_clock_is_within_one_tick():
    packer, parser = PayloadPacker(1024, 48_000_000), PayloadParser(48_000_000)
    t = 50_000_000_123  # within the first 2**32 ticks: the parser takes the first PTS as it comes
    (frame,) = parser.feed_many(packer.pack(b"x" * 100, t, t))
    assert 0 <= t - frame.pts_ns < 1e9 / 48e6 + 1
    assert ticks_to_ns(48_000_000, 48_000_000) == 10**9


def test_lost_packets_fid_toggles_and_err_are_reported():
    packer = PayloadPacker(112, 10**9)  # 100 data bytes per payload
    parser = PayloadParser(10**9, 1000)
    a, b, c = (list(packer.pack(_frame(1000, i), i, i)) for i in range(3))
    out = parser.feed_many(a[:4] + a[5:])  # one payload of frame a lost
    assert len(out) == 1 and not out[0].complete
    out = parser.feed_many(b[:-1])  # EOF of b lost: the FID toggle of c ends it
    assert out == []
    out = parser.feed_many(c)
    assert [f.complete for f in out] == [False, True] and out[0].data == b""[:0] + _frame(1000, 1).tobytes()[:900]
    err_batch = packer.pack(_frame(1000, 3), 3, 3, error=True)
    (bad,) = parser.feed_many(err_batch)
    assert bad.error and bad.complete
    parser.feed(b"\x05\x0c\x00")  # malformed header: counted, marks the frame in progress damaged
    (after,) = parser.feed_many(packer.pack(_frame(1000, 4), 4, 4))
    assert after.error
    s = parser.stats
    assert (s.bad_headers, s.incomplete, s.errors, s.frames) == (1, 2, 2, 5)


def test_pts_unwraps_across_32_bits_at_48_mhz():
    packer, parser = PayloadPacker(1024, 48_000_000), PayloadParser(48_000_000)
    period = 33_333_333
    times = [80_000_000_000 + i * period * 20 for i in range(12)]  # spans the 89.5 s wrap of 2**32 ticks
    got = [parser.feed_many(packer.pack(b"y" * 10, t, t))[0].pts_ns for t in times]
    assert all(abs(g - t) <= 21 for g, t in zip(got, times, strict=True))


@pytest.mark.parametrize("fourcc", WIRE_FORMATS)
def test_pixel_formats_round_trip(fourcc):
    y, x = np.mgrid[0:48, 0:64]
    bgr = np.dstack([x * 3, y * 4, (x + y) * 2]).astype(np.uint8)
    raw = encode(bgr, fourcc)
    layout = wire_layout(fourcc)
    if layout is not None:
        assert raw.size == layout.sizeimage(64, 48) == {"YUYV": 64 * 48 * 2, "NV12": 64 * 48 * 3 // 2}[fourcc]
    back = decode(raw.tobytes(), fourcc, 64, 48)
    assert back.shape == bgr.shape
    assert np.abs(back.astype(int) - bgr).mean() < 4
    with pytest.raises(ProtocolError):
        decode(raw.tobytes()[:-2] if fourcc != "MJPG" else b"not a jpeg", fourcc, 64, 48)


def test_a_reference_time_gives_the_first_pts_its_high_bits():
    t = 3 * (1 << 32) + 123_456  # ns at 1 GHz: past three wraps
    packer = PayloadPacker(1024, 10**9)
    for ref in (t, t + 2_000_000_000, t - 2_000_000_000):
        parser = PayloadParser(10**9, reference_ns=ref)
        (a,) = parser.feed_many(packer.pack(b"z" * 10, t, t))
        (b,) = parser.feed_many(packer.pack(b"z" * 10, t + 33_333_333, t))
        assert (a.pts_ns, b.pts_ns) == (t, t + 33_333_333)
    (plain,) = PayloadParser(10**9).feed_many(packer.pack(b"z", t, t))
    assert plain.pts_ns == t % (1 << 32)


def test_frames_finished_in_one_batch_get_their_own_index():
    from rollcam.emu.uvc import PayloadPacker, PayloadParser

    packer = PayloadPacker(payload_size=1024, clock_hz=1_000_000_000)
    batches = [packer.pack(bytes([k]) * 300, 1_000_000 * (k + 1), 1_000_000 * (k + 1)) for k in range(3)]
    stream = b"".join(bytes(b.buffer) for b in batches)
    lengths = np.concatenate([b.lengths for b in batches])
    frames = PayloadParser(clock_hz=1_000_000_000).feed_batch(stream, lengths)  # one read, three frames
    assert [f.index for f in frames] == [0, 1, 2]
    assert [f.data[:1] for f in frames] == [b"\x00", b"\x01", b"\x02"]


def test_wire_layouts_come_from_the_fourcc_table_and_unknown_formats_are_refused():
    assert wire_layout("MJPG") is None
    assert wire_layout("YUYV").shape(64, 48) == (48, 64, 2) and wire_layout("NV12").shape(64, 48) == (72, 64)
    with pytest.raises(ProtocolError, match="H264"):
        wire_layout("H264")
    with pytest.raises(ProtocolError, match="H264"):
        decode(b"\0" * 10, "H264", 4, 4)
