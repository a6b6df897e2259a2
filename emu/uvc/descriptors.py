"""UVC 1.5 descriptor codec: pure functions that build the camera's descriptor set and parse one back.

``build_descriptors`` makes the device descriptor, the configuration (IAD, VideoControl interface with a camera
terminal, a processing unit and an output terminal, VideoStreaming interface with YUYV, NV12 and MJPEG formats,
their frame sizes and intervals in 100 ns units) and the string table. The streaming interface is isochronous
(alternate setting 0 without bandwidth plus one alternate setting per max packet size) or bulk (one endpoint on
alternate setting 0). ``parse_streaming`` is the host-side reader that recovers the format/frame tables from a
configuration descriptor, emulated or real.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass, field

from rollcam.common.errors import ProtocolError
from rollcam.common.values import SERIAL

from . import constants as C

GUID_TAIL = b"\x00\x00\x10\x00\x80\x00\x00\xaa\x00\x38\x9b\x71"
"""The common tail of the uncompressed-format GUIDs (``XXXX-0000-0010-8000-00AA00389B71``)."""

FORMATS = {"YUYV": (b"YUY2" + GUID_TAIL, 16), "NV12": (b"NV12" + GUID_TAIL, 12), "MJPG": (None, 0)}
"""Wire formats: V4L2 fourcc -> (GUID or None for MJPEG, bits per pixel)."""

ISO_PACKET_SIZES = (512, 1024, 2048, 3072)
"""Bytes per microframe of the isochronous alternate settings 1..n (high-bandwidth above 1024)."""

STREAM_EP = 0x81
HEADER_MAX = 12


@dataclass(frozen=True)
class FrameSize:
    """One frame descriptor: size, the frame intervals offered (100 ns units) and the default one."""

    width: int
    height: int
    intervals_100ns: tuple[int, ...]
    default_100ns: int | None = None  # None: the first interval

    def __post_init__(self) -> None:
        if self.default_100ns is None and self.intervals_100ns:
            object.__setattr__(self, "default_100ns", self.intervals_100ns[0])


@dataclass(frozen=True)
class StreamFormat:
    """One format descriptor: its fourcc and its frame sizes (1-based indices in descriptor order)."""

    fourcc: str
    frames: tuple[FrameSize, ...]

    def frame_bytes(self, size: FrameSize) -> int:
        """Largest frame of this format at ``size`` (an MJPEG frame is bounded by the raw YUYV size)."""
        bpp = FORMATS[self.fourcc][1] or 16
        return size.width * size.height * bpp // 8


@dataclass(frozen=True)
class DeviceIdentity:
    """What the device descriptor and string table say about the camera."""

    # pid.codes' VID 0x1209 with one of its test PIDs (0x0000-0x0FFF are kept for tests and common tasks), which
    # usb.ids lists as "Generic : pid.codes Test PID": no other product's name. `rollcam emulate --usb-id` and
    # ``DeviceIdentity(vendor_id=..., product_id=...)`` give a camera other IDs (a real camera's, to test a
    # driver's quirk for it).
    vendor_id: int = 0x1209
    product_id: int = 0x0001
    bcd_device: int = 0x0100
    manufacturer: str = "rollcam"
    product: str = "rollcam emulated UVC camera"
    serial: str = SERIAL


@dataclass(frozen=True)
class DescriptorSet:
    """Everything GET_DESCRIPTOR answers: device, configuration (with its tail), strings by index."""

    device: bytes
    configuration: bytes
    strings: dict[int, str] = field(default_factory=dict)
    iso_packet_sizes: tuple[int, ...] = ()
    clock_hz: int = 0


def frame_rates(fmt: StreamFormat, size: FrameSize) -> tuple[int, int, int]:
    """A frame descriptor's (dwMinBitRate, dwMaxBitRate, dwMaxVideoFrameBufferSize): the largest frame's bits at
    the slowest and the fastest interval offered, and that frame's bytes."""
    buf = fmt.frame_bytes(size)
    iv = size.intervals_100ns
    return buf * 8 * 10_000_000 // max(iv), buf * 8 * 10_000_000 // min(iv), buf


def encode_max_packet(size: int) -> int:
    """wMaxPacketSize with the high-bandwidth bits (bits 12..11: extra transactions per microframe)."""
    per = min(size, 1024)
    extra = -(-size // per) - 1
    if extra > 2 or per * (extra + 1) != size:
        raise ProtocolError(f"isochronous packet size {size!r} is not n x {per} with n <= 3")
    return per | (extra << 11)


def decode_max_packet(w: int) -> int:
    """Bytes per microframe of a wMaxPacketSize value."""
    return (w & 0x7FF) * (1 + ((w >> 11) & 3))


def _interface(number: int, alt: int, n_ep: int, subclass: int, string: int = 0) -> bytes:
    return struct.pack("<BBBBBBBBB", 9, C.DT_INTERFACE, number, alt, n_ep, C.CC_VIDEO, subclass,
                       C.PC_PROTOCOL_15, string)


def _endpoint(address: int, attributes: int, max_packet: int, interval: int) -> bytes:
    return struct.pack("<BBBBHB", 7, C.DT_ENDPOINT, address, attributes, max_packet, interval)


def _video_control(clock_hz: int) -> bytes:
    ct = struct.pack("<BBBBHBBHHHB3s", 18, C.CS_INTERFACE, C.VC_INPUT_TERMINAL, C.TERMINAL_CAMERA, C.ITT_CAMERA,
                     0, 0, 0, 0, 0, 3, (0b1010).to_bytes(3, "little"))  # AE mode, exposure time absolute
    pu = struct.pack("<BBBBBHB3sBB", 13, C.CS_INTERFACE, C.VC_PROCESSING_UNIT, C.UNIT_PROCESSING,
                     C.TERMINAL_CAMERA, 0, 3, (1 << 9).to_bytes(3, "little"), 0, 0)  # gain
    ot = struct.pack("<BBBBHBBB", 9, C.CS_INTERFACE, C.VC_OUTPUT_TERMINAL, C.TERMINAL_OUTPUT, C.TT_STREAMING, 0,
                     C.UNIT_PROCESSING, 0)
    body = ct + pu + ot
    header = struct.pack("<BBBHHIBB", 13, C.CS_INTERFACE, C.VC_HEADER, 0x0150, 13 + len(body), clock_hz, 1, 1)
    return header + body


def _formats(formats: Sequence[StreamFormat]) -> bytes:
    out = b""
    for fi, fmt in enumerate(formats, 1):
        guid, bpp = FORMATS[fmt.fourcc]
        n = len(fmt.frames)
        if guid is None:
            out += struct.pack("<BBBBBBBBBBB", 11, C.CS_INTERFACE, C.VS_FORMAT_MJPEG, fi, n, 1, 1, 0, 0, 0, 0)
            frame_subtype = C.VS_FRAME_MJPEG
        else:
            out += struct.pack("<BBBBB16sBBBBBB", 27, C.CS_INTERFACE, C.VS_FORMAT_UNCOMPRESSED, fi, n, guid, bpp,
                               1, 0, 0, 0, 0)
            frame_subtype = C.VS_FRAME_UNCOMPRESSED
        for ri, size in enumerate(fmt.frames, 1):
            iv = size.intervals_100ns
            out += struct.pack(f"<BBBBBHHIIIIB{len(iv)}I", 26 + 4 * len(iv), C.CS_INTERFACE, frame_subtype, ri, 0,
                               size.width, size.height, *frame_rates(fmt, size), size.default_100ns, len(iv), *iv)
        out += struct.pack("<BBBBBB", 6, C.CS_INTERFACE, C.VS_COLORFORMAT, 1, 1, 4)  # BT.709 / sRGB
    return out


def build_descriptors(formats: Sequence[StreamFormat], identity: DeviceIdentity | None = None, *,
                      transfer: str = "iso", clock_hz: int = 1_000_000_000,
                      iso_packet_sizes: Sequence[int] = ISO_PACKET_SIZES) -> DescriptorSet:
    """The camera's full descriptor set for ``formats`` over ``transfer`` ('iso' or 'bulk')."""
    if transfer not in ("iso", "bulk"):
        raise ProtocolError(f"transfer {transfer!r} is not 'iso' or 'bulk'")
    if not formats or any(not f.frames or any(not s.intervals_100ns for s in f.frames) for f in formats):
        raise ProtocolError("every format needs at least one frame size with at least one interval")
    ident = identity or DeviceIdentity()
    device = struct.pack("<BBHBBBBHHHBBBB", 18, C.DT_DEVICE, 0x0200, 0xEF, 0x02, 0x01, 64, ident.vendor_id,
                         ident.product_id, ident.bcd_device, 1, 2, 3, 1)  # misc class / IAD: a composite device
    vc = _video_control(clock_hz)
    fmt = _formats(formats)
    n_fmt = len(formats)
    vs_len = 13 + n_fmt + len(fmt)
    vs_header = struct.pack(f"<BBBBHBBBBBBB{n_fmt}B", 13 + n_fmt, C.CS_INTERFACE, C.VS_INPUT_HEADER, n_fmt, vs_len,
                            STREAM_EP, 0, C.TERMINAL_OUTPUT, 0, 0, 0, 1, *([0] * n_fmt))
    # No iFunction and no iInterface string: uvcvideo appends one to the product's name in a 32-byte field
    # ("rollcam emulated UVC camera: ro"); without them the kernel names the camera by its product string.
    iad = struct.pack("<BBBBBBBB", 8, C.DT_INTERFACE_ASSOCIATION, 0, 2, C.CC_VIDEO,
                      C.SC_VIDEO_INTERFACE_COLLECTION, 0, 0)
    body = iad + _interface(0, 0, 0, C.SC_VIDEOCONTROL, 0) + vc
    if transfer == "bulk":
        body += _interface(1, 0, 1, C.SC_VIDEOSTREAMING) + vs_header + fmt + _endpoint(STREAM_EP, C.EP_XFER_BULK,
                                                                                       512, 0)
        sizes: tuple[int, ...] = ()
    else:
        body += _interface(1, 0, 0, C.SC_VIDEOSTREAMING) + vs_header + fmt
        sizes = tuple(iso_packet_sizes)
        for alt, size in enumerate(sizes, 1):
            body += _interface(1, alt, 1, C.SC_VIDEOSTREAMING)
            body += _endpoint(STREAM_EP, C.EP_XFER_ISOC | C.EP_ISO_ASYNC, encode_max_packet(size), 1)
    config = struct.pack("<BBHBBBBB", 9, C.DT_CONFIGURATION, 9 + len(body), 2, 1, 0, 0x80, 250) + body
    strings = {1: ident.manufacturer, 2: ident.product, 3: ident.serial}
    return DescriptorSet(device, config, strings, sizes, clock_hz)


def string_descriptor(index: int, strings: dict[int, str]) -> bytes:
    """String descriptor ``index`` (0: the language table, US English)."""
    if index == 0:
        return bytes((4, C.DT_STRING, 0x09, 0x04))
    if index not in strings:
        raise KeyError(index)
    text = strings[index].encode("utf-16-le")[:252]
    return bytes((2 + len(text), C.DT_STRING)) + text


# ---------------------------------------------------------------------------------------------- parsing
def split_descriptors(blob: bytes) -> list[bytes]:
    """The descriptors of a concatenated blob, each as bytes; a zero or overrunning bLength is an error."""
    out, i = [], 0
    while i < len(blob):
        n = blob[i]
        if n < 2 or i + n > len(blob):
            raise ProtocolError(f"descriptor at offset {i} has bLength {n!r} (blob of {len(blob)} bytes)")
        out.append(bytes(blob[i:i + n]))
        i += n
    return out


@dataclass(frozen=True)
class StreamingInfo:
    """What a host needs from a configuration to stream: formats, VS interface, endpoint, alt settings."""

    formats: tuple[StreamFormat, ...]
    interface: int
    endpoint: int
    transfer: str
    alt_packet_sizes: dict[int, int]
    clock_hz: int


def parse_streaming(config: bytes) -> StreamingInfo:
    """Read the VideoStreaming formats, frame sizes, endpoint and alternate settings from a configuration."""
    formats: list[StreamFormat] = []
    fourcc, frames = None, []
    interface = endpoint = -1
    alt = 0
    alts: dict[int, int] = {}
    transfer = "iso"
    clock_hz = 0
    cur_intf = (-1, -1, -1)
    for d in split_descriptors(config):
        kind = d[1]
        if kind == C.DT_INTERFACE and len(d) >= 9:
            cur_intf = (d[2], d[3], d[6])
            alt = d[3]
        elif kind == C.CS_INTERFACE and len(d) >= 3:
            sub = d[2]
            if cur_intf[2] == C.SC_VIDEOCONTROL and sub == C.VC_HEADER and len(d) >= 12:
                clock_hz = struct.unpack_from("<I", d, 7)[0]
            elif cur_intf[2] != C.SC_VIDEOSTREAMING:
                continue
            elif sub in (C.VS_FORMAT_UNCOMPRESSED, C.VS_FORMAT_MJPEG):
                if fourcc is not None:
                    formats.append(StreamFormat(fourcc, tuple(frames)))
                frames = []
                fourcc = "MJPG"
                if sub == C.VS_FORMAT_UNCOMPRESSED:
                    guid = d[5:21]
                    fourcc = next((k for k, (g, _) in FORMATS.items() if g == guid), guid[:4].decode("latin-1"))
            elif sub in (C.VS_FRAME_UNCOMPRESSED, C.VS_FRAME_MJPEG) and len(d) >= 26:
                w, h = struct.unpack_from("<HH", d, 5)
                n = d[25]
                ivs = struct.unpack_from(f"<{n}I", d, 26) if n and len(d) >= 26 + 4 * n else \
                    struct.unpack_from("<III", d, 26)[:3] if len(d) >= 38 else ()
                default = struct.unpack_from("<I", d, 21)[0]
                frames.append(FrameSize(w, h, tuple(ivs), default if default in ivs else None))
        elif kind == C.DT_ENDPOINT and len(d) >= 7 and cur_intf[2] == C.SC_VIDEOSTREAMING:
            interface, endpoint = cur_intf[0], d[2]
            wmax = struct.unpack_from("<H", d, 4)[0]
            if d[3] & 3 == C.EP_XFER_BULK:
                transfer = "bulk"
            alts[alt] = decode_max_packet(wmax)
    if fourcc is not None:
        formats.append(StreamFormat(fourcc, tuple(frames)))
    if interface < 0 or not formats:
        raise ProtocolError("configuration has no VideoStreaming interface with an endpoint and a format")
    return StreamingInfo(tuple(formats), interface, endpoint, transfer, alts, clock_hz)
