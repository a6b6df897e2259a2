"""The emulated UVC 1.5 camera as a USB function: standard and class requests on endpoint 0, over the streaming
endpoint's transfers (``transfers.py``) and payload source (``stream.py``).

``UVCFunction`` is what every USB transport drives (the pyusb backend in process, the USB/IP server over TCP):
``control(setup, data)`` answers a control transfer or raises ``Stall``; ``read(endpoint, max_len, timeout_ms)``
returns one payload (a bulk transfer, or one isochronous packet). In real-time mode frames are sent at their
device times and a host that reads too slowly skips to the newest frame, the skipped ones counted in
``stats.frames_dropped``; only the frame being sent is held, so memory stays bounded whatever the host does.
An isochronous endpoint in real-time mode also keeps the bus's pace: one packet per service interval of the
selected alternate setting's endpoint (bInterval; a packet carries up to mult x wMaxPacketSize bytes), so
packets arrive no faster than a high-speed bus carries them (8,000 a second at bInterval 1).
A fault plan (``faults``: ``rollcam.common.faults``) stalls class requests, drops, flags and damages what
the stream sends (``stream.py``, ``faults.py``) and unplugs the device: from then on every request fails
with ``Disconnected`` until the host enumerates it again (``reset()``; ``plug.generation`` counts plug-ins).
"""

from __future__ import annotations

import struct
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from rollcam.common.faults import FaultInjector, FaultPlan
from rollcam.common.lifecycle import Closeable

from . import constants as C
from .descriptors import (
    STREAM_EP,
    DescriptorSet,
    DeviceIdentity,
    FrameSize,
    StreamFormat,
    build_descriptors,
    split_descriptors,
    string_descriptor,
)
from .faults import Plug
from .producer import FrameProducer
from .requests import Stall, VideoControls
from .stream import BusSchedule, StreamEndpoint, service_interval_ns
from .transfers import StreamTransfers

DEFAULT_BULK_PAYLOAD = 512 * 1024
MICROFRAMES_PER_S = 8000


@dataclass(frozen=True)
class Setup:
    """The 8-byte SETUP packet of a control transfer."""

    bmRequestType: int
    bRequest: int
    wValue: int
    wIndex: int
    wLength: int

    @classmethod
    def unpack(cls, raw: bytes) -> Setup:
        return cls(*struct.unpack("<BBHHH", raw))

    def pack(self) -> bytes:
        return struct.pack("<BBHHH", self.bmRequestType, self.bRequest, self.wValue, self.wIndex, self.wLength)

    @property
    def is_in(self) -> bool:
        return bool(self.bmRequestType & C.DIR_IN)


class UVCFunction(Closeable):
    """A UVC 1.5 camera function over a ``FrameProducer``: descriptors, requests and the stream; a context
    manager (closing stops the stream)."""

    def __init__(self, producer: FrameProducer, *, fourccs: Sequence[str] = ("YUYV", "NV12", "MJPG"),
                 transfer: str = "iso", identity: DeviceIdentity | None = None, clock_hz: int = 1_000_000_000,
                 realtime: bool = False, bulk_payload_size: int = DEFAULT_BULK_PAYLOAD,
                 sleep: Callable[[float], None] = time.sleep, render_ahead: bool = True,
                 faults: FaultPlan | str | None = None) -> None:
        self.producer = producer
        self.injector = FaultInjector(FaultPlan.of(faults))
        self.fault_stats = self.injector.stats
        self.plug = Plug()  # unplugged by an injected disconnect until the host enumerates the device again
        self._class_requests = 0
        self.realtime = realtime
        self.transfer = transfer
        self._lock = threading.RLock()
        formats, intervals = offered_formats(producer, fourccs)
        self.descriptors: DescriptorSet = build_descriptors(formats, identity, transfer=transfer, clock_hz=clock_hz)
        self.formats = formats
        self.clock_hz = clock_hz
        self._bulk_payload = int(bulk_payload_size)
        self.controls = VideoControls(producer, formats, intervals, clock_hz, self._payload_size)
        self.configuration = 0
        self.alt = {0: 0, 1: 0}
        self.stream = StreamEndpoint(producer, clock_hz, realtime, sleep, render_ahead, faults=self.injector,
                                     bulk=transfer == "bulk")
        self.stats = self.stream.stats
        self._transfers = StreamTransfers(self.stream, self.controls, transfer, self._lock, producer.now_ns, sleep,
                                          lambda: bool(self.configuration))

    def __repr__(self) -> str:
        c = self.controls.committed
        what = f"{c.fourcc} {c.width}x{c.height}" if c else "not committed"
        return f"UVCFunction({self.producer.name!r}, {self.transfer}, {what}, streaming={self.streaming})"

    # ------------------------------------------------------------------------------------ control
    def control(self, setup: Setup, data: bytes = b"") -> bytes:
        """Answer one control transfer: IN returns up to wLength bytes, OUT returns b''; refusals raise Stall."""
        with self._lock:
            self.plug.check()
            try:
                kind = setup.bmRequestType & C.TYPE_MASK
                if kind == C.TYPE_STANDARD:
                    out = self._standard(setup)
                elif kind == C.TYPE_CLASS and setup.bmRequestType & C.RECIP_MASK == C.RECIP_INTERFACE:
                    if self.configuration == 0:
                        raise Stall("class request before SET_CONFIGURATION", C.ERR_WRONG_STATE)
                    direction_ok = setup.is_in == (setup.bRequest != C.SET_CUR)
                    if not direction_ok:
                        raise Stall(f"request {setup.bRequest:#04x} with direction bit {setup.is_in}",
                                    C.ERR_INVALID_REQUEST)
                    self._class_requests += 1
                    if self.injector.hit("stall", self._class_requests - 1, "control"):
                        raise Stall(f"injected STALL of class request {setup.bRequest:#04x}", C.ERR_UNKNOWN)
                    out = self.controls.request(setup.bRequest, setup.wIndex & 0xFF, setup.wIndex >> 8,
                                                setup.wValue >> 8, setup.wLength, bytes(data))
                else:
                    raise Stall(f"bmRequestType {setup.bmRequestType:#04x} is not handled", C.ERR_INVALID_REQUEST)
            except Stall:
                self.stats.stalls += 1
                raise
            return out[: setup.wLength] if setup.is_in else b""

    def _standard(self, s: Setup) -> bytes:
        r, recip = s.bRequest, s.bmRequestType & C.RECIP_MASK
        if r == C.REQ_GET_DESCRIPTOR and s.is_in:
            return self._descriptor(s.wValue >> 8, s.wValue & 0xFF)
        if r == C.REQ_GET_STATUS and s.is_in:
            return b"\x00\x00"
        if r == C.REQ_GET_CONFIGURATION and s.is_in:
            return bytes((self.configuration,))
        if r == C.REQ_GET_INTERFACE and s.is_in:
            if s.wIndex not in self.alt:
                raise Stall(f"no interface {s.wIndex}", C.ERR_INVALID_UNIT)
            return bytes((self.alt[s.wIndex],))
        if s.is_in:
            raise Stall(f"standard IN request {r:#04x} is not supported", C.ERR_INVALID_REQUEST)
        if r == C.REQ_SET_CONFIGURATION:
            if s.wValue not in (0, 1):
                raise Stall(f"configuration {s.wValue} does not exist", C.ERR_INVALID_VALUE)
            self._stop_stream()
            self.configuration = s.wValue
            self.alt = {0: 0, 1: 0}
            return b""
        if r == C.REQ_SET_INTERFACE:
            self.set_interface(s.wIndex, s.wValue)
            return b""
        if r == C.REQ_CLEAR_FEATURE and recip == C.RECIP_ENDPOINT:
            if s.wIndex == STREAM_EP and self.transfer == "bulk":
                self._stop_stream()  # how a UVC host stops a bulk stream
            return b""
        if r in (C.REQ_SET_ADDRESS, C.REQ_SET_FEATURE, C.REQ_CLEAR_FEATURE):
            return b""
        raise Stall(f"standard request {r:#04x} is not supported", C.ERR_INVALID_REQUEST)

    def _descriptor(self, kind: int, index: int) -> bytes:
        d = self.descriptors
        if kind == C.DT_DEVICE:
            return d.device
        if kind == C.DT_CONFIGURATION and index == 0:
            return d.configuration
        if kind == C.DT_STRING:
            try:
                return string_descriptor(index, d.strings)
            except KeyError:
                raise Stall(f"no string {index}", C.ERR_OUT_OF_RANGE) from None
        if kind == C.DT_DEVICE_QUALIFIER:
            return struct.pack("<BBH4BBB", 10, C.DT_DEVICE_QUALIFIER, 0x0200, *d.device[4:8], 1, 0)
        raise Stall(f"no descriptor of type {kind:#04x} index {index}", C.ERR_OUT_OF_RANGE)

    def set_interface(self, interface: int, alt: int) -> None:
        """SET_INTERFACE: on the streaming interface of an isochronous camera, alt > 0 starts the stream."""
        with self._lock:
            n_alt = len(self.descriptors.iso_packet_sizes) + 1 if interface == 1 else 1
            if self.configuration == 0 or interface not in self.alt or not 0 <= alt < n_alt:
                raise Stall(f"interface {interface} has no alternate setting {alt}", C.ERR_INVALID_VALUE)
            self.alt[interface] = alt
            if interface == 1 and self.transfer == "iso":
                self._stop_stream()
                if alt:
                    if self.controls.committed is None:
                        raise Stall("alternate setting selected before commit", C.ERR_WRONG_STATE)
                    self._transfers.start(self.descriptors.iso_packet_sizes[alt - 1],
                                          service_interval_ns(self._iso_endpoint(alt)))

    def _iso_endpoint(self, alt: int) -> bytes:
        """The endpoint descriptor of the streaming interface's alternate setting ``alt``."""
        current = None
        for d in split_descriptors(self.descriptors.configuration):
            if d[1] == C.DT_INTERFACE:
                current = (d[2], d[3])
            elif d[1] == C.DT_ENDPOINT and current == (1, alt):
                return d
        raise Stall(f"alternate setting {alt} has no endpoint", C.ERR_INVALID_VALUE)

    def _payload_size(self, frame_bytes: int, interval_ns: int) -> int:
        if self.transfer == "bulk":
            return self._bulk_payload
        return iso_payload_size(frame_bytes, interval_ns, max(self.descriptors.iso_packet_sizes))

    # ------------------------------------------------------------------------------------- stream
    @property
    def streaming(self) -> bool:
        """Whether the streaming endpoint is running."""
        return self._transfers.active

    @property
    def bus(self) -> BusSchedule:
        """The service intervals of the isochronous endpoint on the bus (of the selected alternate setting)."""
        return self._transfers.bus

    def _stop_stream(self) -> None:
        self._transfers.stop()

    def mark_errors(self, n_frames: int) -> None:
        """Fault injection: the next ``n_frames`` frames go out with ERR set in their payload headers."""
        with self._lock:
            self.stream.mark_errors(n_frames)

    def reset(self) -> None:
        """The host detached, or enumerates a device that was unplugged: stop streaming, unconfigure (a
        mid-frame stop is counted as aborted); an unplugged device is plugged in again (``generation`` + 1)."""
        with self._lock:
            self._stop_stream()
            self.configuration = 0
            self.alt = {0: 0, 1: 0}
            self.plug.replug()

    def _halt_stream(self) -> None:
        with self._lock:
            self._stop_stream()

    def _close(self) -> None:
        """Stop streaming (and the renderer thread of real-time mode)."""
        self.reset()

    def read(self, endpoint: int, max_len: int, timeout_ms: int | None = None) -> bytes:
        """One isochronous packet or bulk transfer from the streaming endpoint (``transfers.StreamTransfers.read``):
        b'' when an isochronous stream has nothing due; a bulk read waits up to ``timeout_ms`` (None or 0:
        forever) and returns at most ``max_len`` bytes of the payload stream, a longer payload going on in the
        next reads."""
        with self.plug.watch(self._halt_stream):
            return self._transfers.read(endpoint, max_len, timeout_ms)

    def read_packets(self, endpoint: int, n_packets: int, max_len: int) -> tuple[bytes, list[int], list[int]]:
        """An isochronous URB's worth of packets: their data back to back, their lengths and their statuses
        (0, or -errno for a packet that failed)."""
        with self.plug.watch(self._halt_stream):
            return self._transfers.read_packets(endpoint, n_packets, max_len)


Intervals = dict[tuple[int, int], tuple[tuple[int, int], ...]]
"""(format index, frame index), 1-based -> the intervals offered: ((100 ns units, exact ns), ...), ascending."""


def offered_formats(producer: FrameProducer, fourccs: Sequence[str]) -> tuple[tuple[StreamFormat, ...], Intervals]:
    """The formats a camera offers (each of ``fourccs`` at every size of the producer, with its intervals) and
    their exact periods: what the descriptors advertise and what probe/commit negotiates, from one place."""
    intervals: Intervals = {}
    frames = []
    for w, h in producer.sizes():
        offered = list(producer.intervals_ns(w, h))  # the first is the default
        ns = sorted(set(offered))
        units = tuple(dict.fromkeys(_units(n) for n in ns))
        frames.append((FrameSize(w, h, units, _units(offered[0])), ns))
    formats = tuple(StreamFormat(f, tuple(fs for fs, _ in frames)) for f in fourccs)
    for fi in range(1, len(formats) + 1):
        for ri, (_, ns) in enumerate(frames, 1):
            intervals[(fi, ri)] = tuple((_units(n), n) for n in ns)
    return formats, intervals


def iso_payload_size(frame_bytes: int, interval_ns: int, max_packet: int) -> int:
    """dwMaxPayloadTransferSize of an isochronous stream: a frame's bytes spread over the microframes of one
    interval, plus a header, capped at the largest packet the endpoint carries per microframe."""
    per_uframe = -(-frame_bytes * 1_000_000_000 // (interval_ns * MICROFRAMES_PER_S)) + 12
    return min(per_uframe, max_packet)


def _units(interval_ns: int) -> int:
    """A frame period in the 100 ns units of UVC descriptors and probes."""
    return max(round(interval_ns / 100), 1)
