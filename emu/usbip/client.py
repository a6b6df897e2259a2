"""A USB/IP client: list a server's devices, import one, and run control, bulk and isochronous transfers on it.

It speaks the same protocol as the Linux vhci-hcd driver and the ``usbip`` tool, so it serves as a test
client for ``USBIPServer`` and as a transport for the ``uvc:`` source (``?usbip=HOST:PORT``). Transfers are
synchronous: one URB out, its reply in (``submit`` can also leave URBs outstanding, which ``unlink`` cancels).
"""

from __future__ import annotations

import contextlib
import errno
import itertools
import socket
import struct

from rollcam.common.errors import DeviceError, ProtocolError
from rollcam.common.lifecycle import Closeable

from . import protocol as P
from .server import DEFAULT_PORT


class UrbError(DeviceError):
    """A URB completed with a negative status (``status``: -errno, e.g. -EPIPE for a STALL)."""

    def __init__(self, message: str, status: int) -> None:
        super().__init__(message)
        self.status = status


def _connect(host: str, port: int, timeout_s: float) -> socket.socket:
    sock = socket.create_connection((host, port), timeout=timeout_s)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return sock


def list_devices(host: str = "127.0.0.1", port: int = DEFAULT_PORT, timeout_s: float = 5.0) -> list[P.ExportedDevice]:
    """The devices a server exports (``usbip list -r HOST``)."""
    with _connect(host, port, timeout_s) as sock:
        sock.sendall(P.op_header(P.OP_REQ_DEVLIST))
        recv = P.socket_reader(sock)
        _v, code, status = P.read_op_header(recv)
        if code != P.OP_REP_DEVLIST or status != P.ST_OK:
            raise ProtocolError(f"device list answered with code {code:#06x} status {status}")
        (n,) = struct.unpack(">I", recv(4))
        if n > 4096:
            raise ProtocolError(f"device list claims {n} devices")
        return [P.ExportedDevice.read(recv, with_interfaces=True) for _ in range(n)]


class ImportedDevice(Closeable):
    """A device imported over USB/IP (``usbip attach`` without the kernel): URBs on one connection."""

    def __init__(self, host: str, port: int, busid: str, timeout_s: float = 10.0) -> None:
        self._sock = _connect(host, port, timeout_s)
        self._recv = P.socket_reader(self._sock)
        self._seq = itertools.count(1)
        self._outstanding: dict[int, P.Submit] = {}
        self._early: dict[int, P.RetSubmit | P.RetUnlink] = {}
        try:
            self._sock.sendall(P.req_import(busid))
            _v, code, status = P.read_op_header(self._recv)
            if code != P.OP_REP_IMPORT or status != P.ST_OK:
                raise DeviceError(f"USB/IP server {host}:{port} refused to import {busid!r}: "
                                  f"{P.status_text(status)}")
            self.info = P.ExportedDevice.read(self._recv, with_interfaces=False)
        except BaseException:
            self.close()
            raise

    def __repr__(self) -> str:
        info = getattr(self, "info", None)
        if info is None:
            return "ImportedDevice(not imported)"
        return f"ImportedDevice({info.busid}, {info.idVendor:04x}:{info.idProduct:04x})"

    def _close(self) -> None:
        """Leave the server (it resets the device for the next importer)."""
        with contextlib.suppress(OSError):
            self._sock.close()

    # -------------------------------------------------------------------------------- raw URBs
    def submit(self, ep: int, direction: int, length: int, *, setup: bytes = bytes(8), data: bytes = b"",
               iso_lengths: tuple[int, ...] = ()) -> int:
        """Send one CMD_SUBMIT; returns its seqnum (collect the reply with ``reply``)."""
        self._check_open()
        seq = next(self._seq)
        iso = tuple(P.IsoPacket(off, n) for off, n in zip(itertools.accumulate((0, *iso_lengths)), iso_lengths,
                                                              strict=False))
        urb = P.Submit(seq, self.info.devid, direction, ep, 0, length, 0, len(iso) if iso else P.NON_ISO, 1, setup,
                       data, iso)
        self._outstanding[seq] = urb
        self._sock.sendall(urb.pack())
        return seq

    def unlink(self, seqnum: int) -> int:
        """Send CMD_UNLINK for ``seqnum``; returns its seqnum."""
        self._check_open()
        seq = next(self._seq)
        self._sock.sendall(P.Unlink(seq, self.info.devid, P.DIR_OUT, 0, seqnum).pack())
        return seq

    def reply(self) -> P.RetSubmit | P.RetUnlink:
        """The next reply from the server (replies that arrived while waiting for another come first)."""
        if self._early:
            return self._early.pop(next(iter(self._early)))
        return self._read_reply()

    def _read_reply(self) -> P.RetSubmit | P.RetUnlink:
        rep = P.read_reply(self._recv, self._outstanding)
        if isinstance(rep, P.RetSubmit):
            self._outstanding.pop(rep.seqnum, None)
        return rep

    def _wait(self, seq: int) -> P.RetSubmit:
        rep = self._early.pop(seq, None)
        while rep is None:
            got = self._read_reply()
            if got.seqnum == seq:
                rep = got
            else:
                self._early[got.seqnum] = got  # another URB's reply: keep it for whoever asks
        if not isinstance(rep, P.RetSubmit):
            raise ProtocolError(f"seqnum {seq} answered by {type(rep).__name__}")
        if rep.status < 0:
            name = errno.errorcode.get(-rep.status, str(rep.status))
            raise UrbError(f"URB {seq} failed with -{name}", rep.status)
        return rep

    # ------------------------------------------------------------------------------- transfers
    def control(self, bmRequestType: int, bRequest: int, wValue: int = 0, wIndex: int = 0,
                data_or_length: bytes | int = 0) -> bytes:
        """A control transfer on endpoint 0: IN returns the data, OUT returns b''. A STALL raises UrbError."""
        is_in = bool(bmRequestType & 0x80)
        length = data_or_length if is_in else len(data_or_length)
        setup = struct.pack("<BBHHH", bmRequestType, bRequest, wValue, wIndex, length)
        seq = self.submit(0, P.DIR_IN if is_in else P.DIR_OUT, length, setup=setup,
                          data=b"" if is_in else bytes(data_or_length))
        return self._wait(seq).data

    def bulk_read(self, ep: int, length: int) -> bytes:
        """One bulk IN transfer of up to ``length`` bytes."""
        return self._wait(self.submit(ep & 0x0F, P.DIR_IN, length)).data

    def iso_read_batch(self, ep: int, n_packets: int, packet_size: int) -> tuple[bytes, list[int]]:
        """One isochronous IN URB of ``n_packets`` packets: the packets' data back to back, and their lengths
        (a failed packet counts as empty), ready for ``PayloadParser.feed_batch``."""
        rep = self._wait(self.submit(ep & 0x0F, P.DIR_IN, n_packets * packet_size,
                                     iso_lengths=(packet_size,) * n_packets))
        if all(p.status == 0 for p in rep.iso):
            return rep.data, [p.actual_length for p in rep.iso]
        parts, pos = [], 0
        for p in rep.iso:
            parts.append(rep.data[pos:pos + p.actual_length] if p.status == 0 else b"")
            pos += p.actual_length
        return b"".join(parts), [len(x) for x in parts]

    def iso_read(self, ep: int, n_packets: int, packet_size: int) -> list[bytes]:
        """One isochronous IN URB of ``n_packets`` packets; returns each packet's data."""
        data, lengths = self.iso_read_batch(ep, n_packets, packet_size)
        out, pos = [], 0
        for n in lengths:
            out.append(data[pos:pos + n])
            pos += n
        return out
