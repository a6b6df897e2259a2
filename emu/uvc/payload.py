"""UVC payload codec (UVC 1.5 section 2.4.3.3): frames to payloads with full headers, and payloads back to frames.

Every payload starts with a 12-byte header: bHeaderLength, bmHeaderInfo (FID, EOF, PTS, SCR, ERR, EOH), the
32-bit PTS (start of exposure of the frame, in ticks of dwClockFrequency) and the SCR (source clock when the
payload left the device, plus the 11-bit USB frame number). Tick counts come from integer-ns device time with
integer arithmetic, so at the default 1 GHz clock a PTS converts back to the exact ns.

``PayloadPacker`` cuts a frame into a ``PayloadBatch`` (one buffer, payload lengths) with numpy, as wide as
one isochronous packet or one bulk transfer. ``PayloadParser`` is the host side: it reassembles frames from
payloads in arrival order, recovers the 64-bit PTS across wraps, and tells complete frames from damaged ones
(lost packets, FID toggled before EOF, ERR set, malformed headers), counting each case.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
from rollcam.common.errors import ProtocolError

from .constants import BH_EOF, BH_EOH, BH_ERR, BH_FID, BH_PTS, BH_SCR

HEADER_LEN = 12
NS_PER_S = 1_000_000_000
SOF_PERIOD_NS = 1_000_000  # the USB frame number counts 1 ms frames
_HDR = np.dtype([("len", "u1"), ("info", "u1"), ("pts", "<u4"), ("stc", "<u4"), ("sof", "<u2")])


def ns_to_ticks(t_ns: int | np.ndarray, clock_hz: int) -> int | np.ndarray:
    """Device time in ns -> ticks of ``clock_hz`` (floor), exact in int64 for any time and clock <= 2**32 Hz."""
    return (t_ns // NS_PER_S) * clock_hz + (t_ns % NS_PER_S) * clock_hz // NS_PER_S


def ticks_to_ns(ticks: int, clock_hz: int) -> int:
    """Ticks -> ns (the first ns at or after which ``ns_to_ticks`` gives ``ticks``; exact at 1 GHz)."""
    return (ticks // clock_hz) * NS_PER_S + -(-(ticks % clock_hz) * NS_PER_S // clock_hz)


def pack_header(fid: int, *, eof: bool = False, pts: int | None = None, scr: tuple[int, int] | None = None,
                err: bool = False) -> bytes:
    """One payload header (2, 6, 8 or 12 bytes) with EOH set."""
    info = (fid & 1) | BH_EOH | (BH_EOF if eof else 0) | (BH_ERR if err else 0)
    body = b""
    if pts is not None:
        info |= BH_PTS
        body += (pts & 0xFFFFFFFF).to_bytes(4, "little")
    if scr is not None:
        info |= BH_SCR
        body += (scr[0] & 0xFFFFFFFF).to_bytes(4, "little") + (scr[1] & 0x7FF).to_bytes(2, "little")
    return bytes((2 + len(body), info)) + body


@dataclass(frozen=True)
class Header:
    """A parsed payload header."""

    length: int
    info: int
    pts: int | None
    scr: tuple[int, int] | None

    @property
    def fid(self) -> int:
        return self.info & BH_FID


def parse_header(payload: bytes | memoryview) -> Header:
    """Parse the header at the start of ``payload``; a malformed one raises ProtocolError."""
    n = len(payload)
    if n < 2:
        raise ProtocolError(f"payload of {n} bytes has no header")
    hl, info = payload[0], payload[1]
    need = 2 + (4 if info & BH_PTS else 0) + (6 if info & BH_SCR else 0)
    if hl < need or hl > n:
        raise ProtocolError(f"payload header length {hl!r} does not fit bmHeaderInfo {info:#04x} "
                            f"(needs {need}) in a payload of {n} bytes")
    pos = 2
    pts = scr = None
    if info & BH_PTS:
        pts = int.from_bytes(payload[2:6], "little")
        pos = 6
    if info & BH_SCR:
        scr = (int.from_bytes(payload[pos:pos + 4], "little"), int.from_bytes(payload[pos + 4:pos + 6], "little")
               & 0x7FF)
    return Header(hl, info, pts, scr)


@dataclass(frozen=True)
class PayloadBatch:
    """Payloads back to back in one buffer: payload ``i`` is ``buffer[offsets[i]:offsets[i] + lengths[i]]``."""

    buffer: np.ndarray
    lengths: np.ndarray
    offsets: np.ndarray

    def __len__(self) -> int:
        return len(self.lengths)

    def __getitem__(self, i: int) -> memoryview:
        o = int(self.offsets[i])
        return memoryview(self.buffer)[o:o + int(self.lengths[i])]

    def __iter__(self) -> Iterator[memoryview]:
        mv = memoryview(self.buffer)
        for o, n in zip(self.offsets.tolist(), self.lengths.tolist(), strict=True):
            yield mv[o:o + n]

    @property
    def nbytes(self) -> int:
        return int(self.buffer.size)


class PayloadPacker:
    """Cuts frames into payloads of at most ``payload_size`` bytes; FID toggles from one frame to the next."""

    def __init__(self, payload_size: int, clock_hz: int, *, send_step_ns: int = 125_000) -> None:
        if payload_size <= HEADER_LEN:
            raise ProtocolError(f"payload size {payload_size!r} leaves no room after the {HEADER_LEN}-byte header")
        if not 0 < clock_hz <= 0xFFFFFFFF:
            raise ProtocolError(f"dwClockFrequency {clock_hz!r} is not in 1..2**32-1")
        self.payload_size = int(payload_size)
        self.clock_hz = int(clock_hz)
        self.send_step_ns = int(send_step_ns)  # one payload per (micro)frame: its SCR advances by this
        self.fid = 0

    def buffer_size(self, frame_bytes: int, extra: int = 0) -> int:
        """Bytes ``pack`` needs to build the payloads of a frame of ``frame_bytes`` (``extra`` header bytes)."""
        chunk = self.payload_size - HEADER_LEN
        first = self.payload_size - HEADER_LEN - extra
        return (1 + max(-(-(frame_bytes - first) // chunk), 0)) * self.payload_size

    def pack(self, data: bytes | np.ndarray, pts_ns: int, send_ns: int, *, error: bool = False,
             out: np.ndarray | None = None, extra: bytes = b"") -> PayloadBatch:
        """The payloads of one frame: PTS ``pts_ns``, SCR from ``send_ns`` on, EOF on the last, ERR if ``error``;
        ``extra`` (metadata items, ``uvc.metadata``) extends the first payload's header past the standard bytes.

        ``out`` (uint8, at least ``buffer_size(len(data), len(extra))`` bytes) is built in instead of a new
        buffer; a streaming endpoint reuses one, so frames cost no fresh pages (the batch lives until ``out`` is
        reused).
        """
        raw = np.frombuffer(data, np.uint8) if isinstance(data, (bytes, bytearray, memoryview)) else \
            np.ascontiguousarray(data).reshape(-1).view(np.uint8)
        ps, chunk = self.payload_size, self.payload_size - HEADER_LEN
        h0 = HEADER_LEN + len(extra)
        if h0 > min(255, ps - 1):
            raise ProtocolError(f"a {h0}-byte payload header does not fit 255 bytes and a {ps}-byte payload")
        size = raw.size
        first = min(size, ps - h0)  # the first payload's data, after its longer header
        n = 1 + max(-(-(size - first) // chunk), 0)
        hdr = np.empty(n, _HDR)
        hdr["len"] = HEADER_LEN
        hdr["len"][0] = h0
        info = BH_EOH | BH_PTS | BH_SCR | self.fid | (BH_ERR if error else 0)
        hdr["info"] = info
        hdr["info"][-1] = info | BH_EOF
        hdr["pts"] = ns_to_ticks(int(pts_ns), self.clock_hz) & 0xFFFFFFFF
        send = np.int64(send_ns) + np.arange(n, dtype=np.int64) * self.send_step_ns
        hdr["stc"] = ns_to_ticks(send, self.clock_hz) & 0xFFFFFFFF
        hdr["sof"] = (send // SOF_PERIOD_NS) & 0x7FF
        total = n * HEADER_LEN + len(extra) + size
        buf = np.empty(n * ps, np.uint8) if out is None or out.size < n * ps else out[: n * ps]
        grid = buf.reshape(n, ps)
        grid[:, :HEADER_LEN] = hdr.view(np.uint8).reshape(n, HEADER_LEN)
        grid[0, HEADER_LEN:h0] = np.frombuffer(extra, np.uint8)
        grid[0, h0:h0 + first] = raw[:first]
        lengths = np.full(n, ps, np.int64)
        if n == 1:
            lengths[0] = h0 + first
        else:
            rest = raw[first:]
            full = (n - 2) * chunk
            grid[1:-1, HEADER_LEN:] = rest[:full].reshape(n - 2, chunk)
            tail = rest.size - full
            grid[-1, HEADER_LEN:HEADER_LEN + tail] = rest[full:]
            lengths[-1] = HEADER_LEN + tail
        self.fid ^= 1
        return PayloadBatch(buf[:total], lengths, np.arange(n, dtype=np.int64) * ps)


@dataclass
class ParsedFrame:
    """A frame recovered from payloads: bytes, its PTS (raw and unwrapped ns), how it ended, and ``index``: its
    position among the frames this parser recovered (0, 1, ...; damaged ones count too)."""

    data: bytes
    fid: int
    pts: int | None
    pts_ns: int | None
    scr: tuple[int, int] | None
    error: bool
    complete: bool
    payloads: int
    index: int = 0
    extra: bytes = b""  # the first payload's header bytes after the standard fields (metadata items)

    def __repr__(self) -> str:
        return (f"ParsedFrame({len(self.data)} B, fid={self.fid}, pts_ns={self.pts_ns}, "
                f"{'complete' if self.complete else 'incomplete'}{', ERR' if self.error else ''})")


@dataclass
class ParserStats:
    """Counts of what the parser saw."""

    payloads: int = 0
    empty: int = 0
    bad_headers: int = 0
    frames: int = 0
    complete: int = 0
    errors: int = 0
    incomplete: int = 0


@dataclass
class PayloadParser:
    """Reassembles frames from payloads in arrival order (host side of a UVC stream).

    ``frame_size`` (bytes of an uncompressed frame) marks frames of another size incomplete; leave it None for
    MJPEG. A frame ends at EOF or when FID toggles; ERR or a malformed header marks it damaged. The first PTS
    is taken as it comes (the device clock modulo 2**32 ticks) unless ``reference_ns``, a device time within
    2**31 ticks of it (the device clock read while the first frame arrives), supplies the high bits.
    """

    clock_hz: int
    frame_size: int | None = None
    stats: ParserStats = field(default_factory=ParserStats)
    reference_ns: int | None = None  # a device time within 2.1 s (at 1 GHz) of the first frame's PTS

    def __post_init__(self) -> None:
        self._parts: list[memoryview] = []
        self._fid = -1
        self._pts: int | None = None
        self._scr: tuple[int, int] | None = None
        self._err = False
        self._n = 0
        self._extra = b""
        self._pts_high = 0
        self._last_pts: int | None = None

    def feed(self, payload: bytes | memoryview) -> list[ParsedFrame]:
        """Take one payload; return the frames it completed (zero, one, or two when FID toggled before EOF)."""
        st = self.stats
        st.payloads += 1
        n = len(payload)
        if n == 0:
            st.empty += 1
            return []
        hl = payload[0]
        info = payload[1] if n > 1 else 0
        need = 2 + (4 if info & BH_PTS else 0) + (6 if info & BH_SCR else 0)
        if n < 2 or hl < need or hl > n:
            st.bad_headers += 1
            self._err = True
            return []
        out: list[ParsedFrame] = []
        fid = info & BH_FID
        if self._n and fid != self._fid:
            out.append(self._finish())
        if not self._n:
            self._fid = fid
            self._extra = bytes(payload[need:hl])
        self._n += 1
        if info & BH_ERR:
            self._err = True
        if info & BH_PTS and self._pts is None:
            self._pts = int.from_bytes(payload[2:6], "little")
        if info & BH_SCR:
            p = 6 if info & BH_PTS else 2
            self._scr = (int.from_bytes(payload[p:p + 4], "little"), int.from_bytes(payload[p + 4:p + 6], "little")
                         & 0x7FF)
        if n > hl:
            self._parts.append(payload[hl:] if isinstance(payload, memoryview) else memoryview(payload)[hl:])
        if info & BH_EOF:
            out.append(self._finish())
        return out

    def feed_many(self, payloads) -> list[ParsedFrame]:
        """``feed`` each payload of an iterable (a PayloadBatch, a list of packets) in order."""
        if isinstance(payloads, PayloadBatch):
            return self.feed_batch(payloads.buffer, payloads.lengths)
        out: list[ParsedFrame] = []
        for p in payloads:
            out += self.feed(p)
        return out

    def feed_batch(self, buffer: bytes | np.ndarray, lengths) -> list[ParsedFrame]:
        """Payloads stored back to back in ``buffer`` (an isochronous URB's data, a PayloadBatch).

        Same result as ``feed`` on each payload in turn; headers are checked with numpy and the loop runs
        once per frame boundary, not once per payload. A batch with a malformed header or ERR set takes the
        per-payload path.
        """
        lens = np.asarray(lengths, np.int64)
        buf = np.frombuffer(buffer, np.uint8) if not isinstance(buffer, np.ndarray) else buffer.reshape(-1)
        offs = np.zeros(lens.size, np.int64)
        np.cumsum(lens[:-1], out=offs[1:])
        if lens.size == 0 or int(lens.sum()) > buf.size:
            return self._feed_each(buf, offs, lens)
        keep = lens > 0
        o, n = offs[keep], lens[keep]
        if n.size == 0 or n.min() < 2:
            return self._feed_each(buf, offs, lens)
        hl = buf[o].astype(np.int64)
        info = buf[o + 1]
        need = 2 + np.where(info & BH_PTS, 4, 0) + np.where(info & BH_SCR, 6, 0)
        if ((hl < need) | (hl > n)).any() or (info & BH_ERR).any():
            return self._feed_each(buf, offs, lens)
        self.stats.payloads += lens.size
        self.stats.empty += lens.size - n.size
        fid = (info & BH_FID).astype(np.int8)
        eof = (info & BH_EOF) != 0
        prev_fid = np.empty_like(fid)
        prev_fid[0] = self._fid if self._n else fid[0]
        prev_fid[1:] = fid[:-1]
        prev_eof = np.empty_like(eof)
        prev_eof[0] = self._n == 0
        prev_eof[1:] = eof[:-1]
        cut_before = (fid != prev_fid) & ~prev_eof  # FID toggled before EOF: the frame in progress ends
        starts, ends = (o + hl).tolist(), (o + n).tolist()
        mv = memoryview(buf)
        out: list[ParsedFrame] = []
        bounds = sorted(set(np.flatnonzero(cut_before).tolist()) | {int(i) + 1 for i in np.flatnonzero(eof)}
                        | {0, n.size})
        for a, b in itertools.pairwise(bounds):
            if cut_before[a] and self._n:
                out.append(self._finish())
            if not self._n:
                self._fid = int(fid[a])
                self._extra = bytes(mv[int(o[a]) + int(need[a]):int(o[a]) + int(hl[a])])
            self._n += b - a
            self._parts += [mv[x:y] for x, y in zip(starts[a:b], ends[a:b], strict=True) if y > x]
            if self._pts is None:
                has = np.flatnonzero(info[a:b] & BH_PTS)
                if has.size:
                    p = int(o[a + has[0]]) + 2
                    self._pts = int.from_bytes(mv[p:p + 4], "little")
            has = np.flatnonzero(info[a:b] & BH_SCR)
            if has.size:
                j = a + int(has[-1])
                p = int(o[j]) + (6 if info[j] & BH_PTS else 2)
                self._scr = (int.from_bytes(mv[p:p + 4], "little"), int.from_bytes(mv[p + 4:p + 6], "little")
                             & 0x7FF)
            if eof[b - 1]:
                out.append(self._finish())
        return out

    def _feed_each(self, buf: np.ndarray, offs: np.ndarray, lens: np.ndarray) -> list[ParsedFrame]:
        mv = memoryview(buf)
        out: list[ParsedFrame] = []
        for x, k in zip(offs.tolist(), lens.tolist(), strict=True):
            out += self.feed(mv[x:x + k])  # a payload claimed past the buffer's end arrives truncated
        return out

    def _unwrap(self, pts: int | None) -> int | None:
        if pts is None:
            return None
        if self._last_pts is None and self.reference_ns is not None:
            # The first PTS gets the high bits that put it nearest the reference time.
            ref = ns_to_ticks(int(self.reference_ns), self.clock_hz)
            self._pts_high = max((ref - pts + (1 << 31)) >> 32, 0) << 32
        elif self._last_pts is not None and pts < self._last_pts and self._last_pts - pts > 1 << 31:
            self._pts_high += 1 << 32
        self._last_pts = pts
        return self._pts_high + pts

    def _finish(self) -> ParsedFrame:
        data = b"".join(self._parts)
        complete = self.frame_size is None or len(data) == self.frame_size
        full_pts = self._unwrap(self._pts)
        frame = ParsedFrame(data, self._fid, self._pts,
                            None if full_pts is None else ticks_to_ns(full_pts, self.clock_hz), self._scr,
                            self._err, complete, self._n, self.stats.frames, self._extra)
        st = self.stats
        st.frames += 1
        st.complete += complete and not self._err
        st.errors += self._err
        st.incomplete += not complete
        self._parts = []
        self._pts = self._scr = None
        self._err = False
        self._n = 0
        self._extra = b""
        return frame
