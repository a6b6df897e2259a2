"""The streaming endpoint of the UVC function: frames from the producer, packed into payloads on demand.

Only the frame being sent is held (in one reused buffer), plus in real-time mode the one frame ``RenderAhead``
has ready. In real-time mode a frame goes out once the device clock has passed its readout; a host that reads
too slowly gets the newest completed frame, the ones it missed counted in ``stats.frames_dropped``; a stop
mid-frame counts in ``frames_aborted``. Without render-ahead (``render_ahead=False``) frames are rendered
when the host asks, and frames the host fell behind on are skipped without being rendered. A fault plan
(``faults``) drops frames (never sent), sends frames with ERR set, unplugs the device after N frames
(``Disconnected``), damages payloads (``faults.PayloadFaults``), decided by frame and payload index, and sends
grey, black or frozen images and resets a firmware camera's registers (``rollcam.firmware.labfaults``), decided
by the frame's index in the stream.

A bulk payload larger than the host's transfer continues in the next transfers (``next_bulk``), as on the
wire: a payload is a run of 512-byte packets ended by a short one, or by a zero-length packet when it ends on
a transfer's last byte short of the negotiated maximum, which is how uvcvideo finds a payload's end. An
isochronous packet is one whole payload, so a payload larger than the packet is an overflow there.
"""

from __future__ import annotations

import errno
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from rollcam.common.errors import DeviceError
from rollcam.common.faults import FaultInjector
from rollcam.firmware.labfaults import FrameFaults
from rollcam.sim.frame import Frame

from .ahead import RenderAhead, newest_due
from .convert import encode
from .faults import Disconnected, PayloadFaults, TransferOverflow
from .payload import PayloadBatch, PayloadPacker
from .producer import FrameProducer
from .requests import Committed

MICROFRAME_NS = 125_000
"""A high-speed USB microframe: 8,000 a second."""


class TransferTimeout(DeviceError):
    """No data became ready on an endpoint within the transfer's timeout."""


def service_interval_ns(endpoint_descriptor: bytes) -> int:
    """How often a high-speed isochronous endpoint is served: every 2**(bInterval-1) microframes (USB 2.0
    9.6.6; bInterval 1..16)."""
    b_interval = min(max(endpoint_descriptor[6], 1), 16)
    return MICROFRAME_NS << (b_interval - 1)


class BusSchedule:
    """The service intervals of an isochronous endpoint on the bus: each packet, full or empty, takes one.

    ``book(n, now_ns)`` places ``n`` packets in the next free intervals (none before ``now_ns``: intervals
    nobody asked for are gone, as on a real bus) and returns the device time the last one ends, which is when
    an isochronous URB of ``n`` packets completes. So an endpoint never delivers more than one packet (of up
    to mult x wMaxPacketSize bytes) per interval, 8,000 a second at bInterval 1, however fast the host asks.
    """

    def __init__(self, interval_ns: int = MICROFRAME_NS) -> None:
        if interval_ns <= 0:
            raise ValueError(f"service interval must be > 0 ns, got {interval_ns!r}")
        self.interval_ns = int(interval_ns)
        self._next_ns: int | None = None

    def book(self, n_packets: int, now_ns: int) -> int:
        """Device time (ns) by which ``n_packets`` more packets have been on the bus."""
        start = now_ns if self._next_ns is None else max(self._next_ns, now_ns)
        self._next_ns = start + n_packets * self.interval_ns
        return self._next_ns


@dataclass
class StreamStats:
    """What the streaming endpoint did: frames and payloads sent, frames dropped or aborted."""

    frames_sent: int = 0
    frames_dropped: int = 0
    frames_aborted: int = 0
    payloads_sent: int = 0
    bytes_sent: int = 0
    stalls: int = 0


class StreamEndpoint:
    """Payload source of one UVC function (not thread-safe: the function serialises calls)."""

    def __init__(self, producer: FrameProducer, clock_hz: int, realtime: bool,
                 sleep: Callable[[float], None], render_ahead: bool = True, *,
                 faults: FaultInjector | None = None, bulk: bool = False) -> None:
        self.producer, self.clock_hz, self.realtime, self.sleep = producer, clock_hz, realtime, sleep
        self.render_ahead = render_ahead and realtime
        self.faults = faults or FaultInjector()
        self.payload_faults = PayloadFaults(self.faults, bulk)
        # Image faults and register resets (of a firmware camera's producer: ``FirmwareProducer.camera``).
        self.frame_faults = FrameFaults(self.faults, getattr(producer, "camera", None))
        self._ahead: RenderAhead | None = None
        self.stats = StreamStats()
        self._error_frames = 0
        self._buf = np.empty(0, np.uint8)
        self._packer: PayloadPacker | None = None
        self._batch: PayloadBatch | None = None
        self._pos = 0
        self._rest = memoryview(b"")  # what a bulk transfer left of the payload being sent
        self._whole = 0  # that payload's length
        self._zlp = False  # a bulk payload ended on a transfer's last byte: a zero-length packet ends it

    @property
    def active(self) -> bool:
        return self._packer is not None

    def start(self, committed: Committed, payload_size: int) -> None:
        """Begin a stream of ``committed``'s format in payloads of ``payload_size`` bytes, at frame 0."""
        self.stop()
        self._packer = PayloadPacker(payload_size, self.clock_hz)
        self._format = committed
        self._next_index = 0
        if self.render_ahead:
            self._ahead = RenderAhead(self.producer, lambda f: encode(f.data, committed.fourcc, committed.jpeg_quality),
                                      self.stats)

    def stop(self) -> None:
        """End the stream (a frame cut short counts as aborted); a halted endpoint is usable again."""
        self.payload_faults.clear_halt()
        if self._batch is not None and (self._pos < len(self._batch) or self._rest):
            self.stats.frames_aborted += 1  # the host went away mid-frame
        if self._ahead is not None:
            self._ahead.stop()
            self._ahead = None
        self._packer = None
        self._batch = None
        self._pos = 0
        self._rest = memoryview(b"")
        self._zlp = False

    def mark_errors(self, n_frames: int) -> None:
        """The next ``n_frames`` frames go out with ERR set."""
        self._error_frames += int(n_frames)

    def next_payload(self, max_len: int | None) -> bytes | int:
        """The next payload (``TransferOverflow`` when it is longer than ``max_len``; None: no limit), or the ns
        until the next frame is due (real-time mode)."""
        self.payload_faults.check_halt()
        if self._batch is None or self._pos >= len(self._batch):
            wait_ns = self._next_batch()
            if wait_ns:
                return wait_ns
        payload = self._batch[self._pos]
        if max_len is not None and len(payload) > max_len:
            raise TransferOverflow(f"payload of {len(payload)} bytes does not fit a {max_len}-byte read")
        self._pos += 1
        out = self.payload_faults.apply(payload, self._next_index - 1)  # raises for a payload that fails
        self.stats.payloads_sent += 1
        self.stats.bytes_sent += len(out)
        return out

    def next_bulk(self, max_len: int) -> bytes | int:
        """The next bulk transfer of at most ``max_len`` bytes, or the ns until the next frame is due (real-time
        mode): the rest of the payload being sent, else the next payload, its first ``max_len`` bytes when it
        is longer (the remainder goes out in the following transfers). A payload shorter than the negotiated
        maximum that ends exactly on the transfer's last byte is followed by a zero-length packet."""
        self.payload_faults.check_halt()
        if self._zlp:
            self._zlp = False
            return b""
        if not self._rest:
            got = self.next_payload(None)
            if isinstance(got, int):
                return got
            self._rest = memoryview(got)
            self._whole = len(got)
        out, self._rest = self._rest[:max_len], self._rest[max_len:]
        self._zlp = not self._rest and len(out) == max_len and self._whole < self._packer.payload_size
        return out.tobytes()

    def _next_payloads_faulty(self, n: int, max_len: int) -> tuple[bytes, list[int], list[int], int]:
        """``next_payloads`` one payload at a time through the payload faults: a babbled packet is empty
        with status -EOVERFLOW, the others go on."""
        chunks: list[bytes] = []
        lengths: list[int] = []
        status: list[int] = []
        while len(lengths) < n:
            try:
                got = self.next_payload(max_len)
            except TransferOverflow:
                got = b""
                status.append(-errno.EOVERFLOW)
            else:
                if isinstance(got, int):
                    return b"".join(chunks), lengths, status, got
                status.append(0)
            chunks.append(got)
            lengths.append(len(got))
        return b"".join(chunks), lengths, status, 0

    def next_payloads(self, n: int, max_len: int) -> tuple[bytes, list[int], list[int], int]:
        """Up to ``n`` payloads of at most ``max_len`` bytes each, back to back, with their lengths and
        statuses (0, or -errno for a packet that failed), and the ns until the next frame is due when they
        ran out (0 otherwise). Each frame's run of payloads is copied out in one piece (the packer reuses its
        buffer for the next frame), which makes an isochronous URB of many packets cheap."""
        if self.payload_faults.active:
            return self._next_payloads_faulty(n, max_len)
        chunks: list[bytes] = []
        lengths: list[int] = []
        while len(lengths) < n:
            if self._batch is None or self._pos >= len(self._batch):
                wait_ns = self._next_batch()
                if wait_ns:
                    return b"".join(chunks), lengths, [0] * len(lengths), wait_ns
            b = self._batch
            k = min(n - len(lengths), len(b) - self._pos)
            run = b.lengths[self._pos:self._pos + k]
            if int(run.max()) > max_len:
                raise TransferOverflow(f"payload of {int(run.max())} bytes does not fit a {max_len}-byte packet")
            start = int(b.offsets[self._pos])
            end = int(b.offsets[self._pos + k - 1]) + int(run[-1])  # a frame's payloads are contiguous
            chunks.append(b.buffer[start:end].tobytes())
            lengths += run.tolist()
            self._pos += k
            self.stats.payloads_sent += k
            self.stats.bytes_sent += end - start
        return b"".join(chunks), lengths, [0] * len(lengths), 0

    def _next_frame(self, now: int) -> tuple[int, Frame, np.ndarray] | int:
        """The next frame to send (index, frame, encoded data), or the ns until it is due."""
        p = self.producer
        index = self._next_index
        if self._ahead is not None:
            return self._ahead.take()
        if self.realtime:
            due = p.frame_due_ns(index)
            if due > now:
                return due - now
            newest = newest_due(p, index, now)  # the host fell behind: skip to the newest frame
            self.stats.frames_dropped += newest - index
            index = newest
        frame = p.frame(index)
        return index, frame, encode(frame.data, self._format.fourcc, self._format.jpeg_quality)

    def _next_batch(self) -> int:
        p = self.producer
        now = p.now_ns()
        if self.faults.disconnect_due(self.stats.frames_sent):
            raise Disconnected(f"injected disconnect after {self.stats.frames_sent} frames")
        while True:
            got = self._next_frame(now)
            if isinstance(got, int):
                return got
            index, frame, data = got
            self._next_index = index + 1
            if not self.faults.hit("drop", index):  # an injected drop: the frame never goes on the bus
                break
        faulted = self.frame_faults.apply(frame, index)
        if faulted is not frame:  # an image fault: the frame goes out as the fault made it
            frame, data = faulted, encode(faulted.data, self._format.fourcc, self._format.jpeg_quality)
        err = self._error_frames > 0
        self._error_frames -= err
        err = err or self.faults.hit("error", index)
        send_ns = now if self.realtime else p.frame_due_ns(index)
        extra = insensor_item(frame, self._packer)
        need = self._packer.buffer_size(data.size, len(extra))
        if self._buf.size < need:
            self._buf = np.empty(need, np.uint8)
        # The previous frame's payloads were all copied out by the reads that sent them: its buffer is free.
        self._batch = self._packer.pack(data, frame.timestamp_ns, send_ns, error=err, out=self._buf, extra=extra)
        self._pos = 0
        self.stats.frames_sent += 1
        return 0


def insensor_item(frame: Frame, packer: Any) -> bytes:
    """The frame's in-sensor result as a payload-header metadata item (``uvc.metadata``), or b"" (none, or a
    payload too small to hold one beside the standard header)."""
    from .metadata import MAX_HEADER, encode

    if not frame.insensor or packer.payload_size <= MAX_HEADER:
        return b""
    return encode(frame.insensor, frame.sequence, packer.clock_hz)
