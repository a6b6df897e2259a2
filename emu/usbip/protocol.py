"""USB/IP wire codec (the Linux kernel's Documentation/usb/usbip_protocol.rst), as pure functions and records.

Operation messages (OP_REQ/REP_DEVLIST, OP_REQ/REP_IMPORT) set a connection up; after a successful import the
connection carries URB messages (USBIP_CMD_SUBMIT/RET_SUBMIT, CMD_UNLINK/RET_UNLINK) with isochronous packet
descriptors. Everything is big-endian except the 8-byte SETUP packet, which travels as USB sends it. Decoders
read through a ``recv_exact(n)`` callable and bound every length they are told, so a malformed peer costs a
``ProtocolError``, never unbounded memory.
"""

from __future__ import annotations

import socket
import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from rollcam.common.errors import ProtocolError

VERSION = 0x0111
OP_REQ_DEVLIST = 0x8005
OP_REP_DEVLIST = 0x0005
OP_REQ_IMPORT = 0x8003
OP_REP_IMPORT = 0x0003
# Operation statuses, numbered as Linux's usbip tools decode them (tools/usb/usbip/libsrc/usbip_common.h).
ST_OK = 0
ST_NA = 1  # the request failed (generic)
ST_DEV_BUSY = 2  # the device is exported but imported by someone else
ST_DEV_ERR = 3  # the device is in an error state
ST_NODEV = 4  # no device has the busid asked for
ST_ERROR = 5  # an unexpected request
STATUS_TEXT = {ST_OK: "request completed", ST_NA: "request failed", ST_DEV_BUSY: "device busy (imported by another "
               "client)", ST_DEV_ERR: "device in error state", ST_NODEV: "device not found", ST_ERROR:
               "unexpected request"}

CMD_SUBMIT = 1
CMD_UNLINK = 2
RET_SUBMIT = 3
RET_UNLINK = 4
DIR_OUT = 0
DIR_IN = 1
NON_ISO = 0xFFFFFFFF  # number_of_packets of a non-isochronous URB in newer kernels (0 in older ones)

MAX_TRANSFER = 32 * 1024 * 1024
MAX_ISO_PACKETS = 1024

_OP = struct.Struct(">HHI")
_DEV = struct.Struct(">256s32sIIIHHHBBBBBB")
_BASIC = struct.Struct(">IIIII")
_SUBMIT = struct.Struct(">IiiII8s")
_RET = struct.Struct(">iiiIi8x")
_UNLINK = struct.Struct(">I24x")
_RET_UNLINK = struct.Struct(">i24x")
_ISO = struct.Struct(">IIIi")
URB_HEADER = 48

RecvExact = Callable[[int], bytes]


def socket_reader(sock: socket.socket) -> RecvExact:
    """A ``RecvExact`` over a blocking socket (the socket's own timeout applies to each read)."""
    def recv(n: int) -> bytes:
        buf = bytearray()
        while len(buf) < n:
            chunk = sock.recv(min(n - len(buf), 1 << 20))
            if not chunk:
                raise ConnectionError("peer closed the connection")
            buf += chunk
        return bytes(buf)
    return recv


@dataclass(frozen=True)
class ExportedDevice:
    """One exported device as OP_REP_DEVLIST and OP_REP_IMPORT describe it."""

    path: str
    busid: str
    busnum: int
    devnum: int
    speed: int
    idVendor: int
    idProduct: int
    bcdDevice: int
    bDeviceClass: int
    bDeviceSubClass: int
    bDeviceProtocol: int
    bConfigurationValue: int
    bNumConfigurations: int
    interfaces: tuple[tuple[int, int, int], ...] = ()

    @property
    def devid(self) -> int:
        return (self.busnum << 16) | self.devnum

    def pack(self, with_interfaces: bool) -> bytes:
        """The usbip_usb_device record (plus its interface records for a device list)."""
        head = _DEV.pack(self.path.encode()[:255], self.busid.encode()[:31], self.busnum, self.devnum, self.speed,
                         self.idVendor, self.idProduct, self.bcdDevice, self.bDeviceClass, self.bDeviceSubClass,
                         self.bDeviceProtocol, self.bConfigurationValue, self.bNumConfigurations,
                         len(self.interfaces))
        if not with_interfaces:
            return head
        return head + b"".join(struct.pack(">BBBx", *i) for i in self.interfaces)

    @classmethod
    def read(cls, recv: RecvExact, with_interfaces: bool) -> ExportedDevice:
        f = _DEV.unpack(recv(_DEV.size))
        intfs = tuple(struct.unpack(">BBBx", recv(4))[:3] for _ in range(f[13])) if with_interfaces else ()
        text = [v.split(b"\0", 1)[0].decode("utf-8", "replace") for v in f[:2]]
        return cls(*text, *f[2:13], interfaces=intfs)


def status_text(status: int) -> str:
    """What an operation status means, as the usbip tool words it (with the number)."""
    return f"{STATUS_TEXT.get(status, 'unknown status')} (status {status})"


def op_header(code: int, status: int = ST_OK) -> bytes:
    """The 8-byte header of an operation message."""
    return _OP.pack(VERSION, code, status)


def read_op_header(recv: RecvExact) -> tuple[int, int, int]:
    """(version, code, status) of an operation message; a wrong version is a ProtocolError."""
    version, code, status = _OP.unpack(recv(_OP.size))
    if version >> 8 != VERSION >> 8:
        raise ProtocolError(f"USB/IP version {version:#06x}; expected {VERSION:#06x}")
    return version, code, status


def rep_devlist(devices: list[ExportedDevice]) -> bytes:
    """OP_REP_DEVLIST for ``devices``."""
    return op_header(OP_REP_DEVLIST) + struct.pack(">I", len(devices)) + \
        b"".join(d.pack(with_interfaces=True) for d in devices)


def rep_import(device: ExportedDevice | None, status: int = ST_OK) -> bytes:
    """OP_REP_IMPORT: the device record on success, the bare header otherwise."""
    if device is None or status != ST_OK:
        return op_header(OP_REP_IMPORT, status or ST_NA)
    return op_header(OP_REP_IMPORT) + device.pack(with_interfaces=False)


def req_import(busid: str) -> bytes:
    """OP_REQ_IMPORT for ``busid``."""
    return op_header(OP_REQ_IMPORT) + struct.pack(">32s", busid.encode()[:31])


def read_busid(recv: RecvExact) -> str:
    """The busid field that follows an OP_REQ_IMPORT header."""
    return recv(32).split(b"\0", 1)[0].decode("utf-8", "replace")


@dataclass(frozen=True)
class IsoPacket:
    """One isochronous packet descriptor."""

    offset: int
    length: int
    actual_length: int = 0
    status: int = 0

    def pack(self) -> bytes:
        return _ISO.pack(self.offset, self.length, self.actual_length, self.status)


@dataclass(frozen=True)
class Submit:
    """USBIP_CMD_SUBMIT: one URB, with its OUT data and isochronous packet descriptors."""

    seqnum: int
    devid: int
    direction: int
    ep: int
    transfer_flags: int
    transfer_buffer_length: int
    start_frame: int
    number_of_packets: int
    interval: int
    setup: bytes
    data: bytes = b""
    iso: tuple[IsoPacket, ...] = ()

    @property
    def is_iso(self) -> bool:
        return self.number_of_packets not in (0, NON_ISO)

    def pack(self) -> bytes:
        return (_BASIC.pack(CMD_SUBMIT, self.seqnum, self.devid, self.direction, self.ep)
                + _SUBMIT.pack(self.transfer_flags, self.transfer_buffer_length, self.start_frame,
                               self.number_of_packets, self.interval, self.setup)
                + self.data + b"".join(p.pack() for p in self.iso))


@dataclass(frozen=True)
class Unlink:
    """USBIP_CMD_UNLINK: cancel the URB ``unlink_seqnum``."""

    seqnum: int
    devid: int
    direction: int
    ep: int
    unlink_seqnum: int

    def pack(self) -> bytes:
        return _BASIC.pack(CMD_UNLINK, self.seqnum, self.devid, self.direction, self.ep) + \
            _UNLINK.pack(self.unlink_seqnum)


@dataclass(frozen=True)
class RetSubmit:
    """USBIP_RET_SUBMIT: the outcome of a URB (IN data compacted packet after packet for isochronous)."""

    seqnum: int
    status: int = 0
    actual_length: int = 0
    start_frame: int = 0
    number_of_packets: int = 0
    error_count: int = 0
    data: bytes = b""
    iso: tuple[IsoPacket, ...] = field(default=())

    def pack(self) -> bytes:
        return (_BASIC.pack(RET_SUBMIT, self.seqnum, 0, 0, 0)
                + _RET.pack(self.status, self.actual_length, self.start_frame, self.number_of_packets,
                            self.error_count)
                + self.data + b"".join(p.pack() for p in self.iso))


@dataclass(frozen=True)
class RetUnlink:
    """USBIP_RET_UNLINK: -ECONNRESET when the URB was cancelled, 0 when it had already completed."""

    seqnum: int
    status: int

    def pack(self) -> bytes:
        return _BASIC.pack(RET_UNLINK, self.seqnum, 0, 0, 0) + _RET_UNLINK.pack(self.status)


def _bounded(what: str, value: int, limit: int) -> int:
    if not 0 <= value <= limit:
        raise ProtocolError(f"{what} {value!r} outside 0..{limit}")
    return value


def _iso_packets(recv: RecvExact, n: int) -> tuple[IsoPacket, ...]:
    return tuple(IsoPacket(*f) for f in _ISO.iter_unpack(recv(_ISO.size * n))) if n else ()


def _read_iso(recv: RecvExact, n: int, total: int) -> tuple[IsoPacket, ...]:
    packets = _iso_packets(recv, n)
    for p in packets:
        if p.offset + p.length > total:
            raise ProtocolError(f"iso packet at {p.offset}+{p.length} overruns a {total}-byte buffer")
    return packets


def read_command(recv: RecvExact) -> Submit | Unlink:
    """Decode the next CMD_SUBMIT or CMD_UNLINK from a stream (server side)."""
    command, seqnum, devid, direction, ep = _BASIC.unpack(recv(_BASIC.size))
    if direction not in (DIR_OUT, DIR_IN) or ep > 15:
        raise ProtocolError(f"URB with direction {direction!r} and endpoint {ep!r}")
    if command == CMD_UNLINK:
        return Unlink(seqnum, devid, direction, ep, _UNLINK.unpack(recv(_UNLINK.size))[0])
    if command != CMD_SUBMIT:
        raise ProtocolError(f"URB command {command:#x} is neither CMD_SUBMIT nor CMD_UNLINK")
    flags, length, start, n_pkt, interval, setup = _SUBMIT.unpack(recv(_SUBMIT.size))
    _bounded("transfer_buffer_length", length, MAX_TRANSFER)
    data = recv(length) if direction == DIR_OUT and length else b""
    sub = Submit(seqnum, devid, direction, ep, flags, length, start, n_pkt, interval, setup, data)
    if sub.is_iso:
        _bounded("number_of_packets", n_pkt, MAX_ISO_PACKETS)
        sub = Submit(*[getattr(sub, k) for k in Submit.__dataclass_fields__ if k != "iso"],
                     iso=_read_iso(recv, n_pkt, length))
    return sub


def read_reply(recv: RecvExact, submitted: Mapping[int, Submit]) -> RetSubmit | RetUnlink:
    """Decode the next RET_SUBMIT or RET_UNLINK (client side); ``submitted`` maps seqnum to the URB sent, whose
    direction says whether data follows (IN only) and whether packet descriptors do (isochronous only)."""
    command, seqnum, _devid, _direction, _ep = _BASIC.unpack(recv(_BASIC.size))
    if command == RET_UNLINK:
        return RetUnlink(seqnum, _RET_UNLINK.unpack(recv(_RET_UNLINK.size))[0])
    if command != RET_SUBMIT:
        raise ProtocolError(f"URB reply {command:#x} is neither RET_SUBMIT nor RET_UNLINK")
    urb = submitted.get(seqnum)
    if urb is None:
        raise ProtocolError(f"RET_SUBMIT for seqnum {seqnum} that was never submitted")
    status, actual, start, n_pkt, errors = _RET.unpack(recv(_RET.size))
    _bounded("actual_length", actual, urb.transfer_buffer_length)
    data = recv(actual) if actual and urb.direction == DIR_IN else b""
    iso: tuple[IsoPacket, ...] = ()
    if urb.is_iso:
        _bounded("number_of_packets", n_pkt, len(urb.iso))
        iso = _iso_packets(recv, n_pkt)
    return RetSubmit(seqnum, status, actual, start, n_pkt, errors, data, iso)
