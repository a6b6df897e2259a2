"""The host's transfers on the UVC function's streaming endpoint: bulk reads that wait for a frame, isochronous
packets at the bus's pace, and starting and stopping the stream they read.

``StreamTransfers`` sits between the USB function (``device.py``, which answers control requests and decides
when the stream starts) and the payload source (``stream.StreamEndpoint``). A bulk read waits on the device
clock for the next frame, up to its timeout; an isochronous read returns one packet, empty when nothing is due.
In real-time mode every isochronous packet takes one service interval of the selected alternate setting's
endpoint, so packets arrive no faster than a high-speed bus carries them. Waiting happens outside the function's
lock, so control requests are answered meanwhile.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from rollcam.common.lifecycle import Deadline

from . import constants as C
from .descriptors import STREAM_EP
from .requests import Stall, VideoControls
from .stream import BusSchedule, StreamEndpoint, TransferTimeout


class StreamTransfers:
    """Reads on the streaming IN endpoint of one UVC function, over its ``StreamEndpoint`` and controls.

    ``configured`` says whether the host has set a configuration (a bulk stream starts on the first read after
    commit, once configured); ``lock`` is the function's, held while the stream's state changes.
    """

    def __init__(self, endpoint: StreamEndpoint, controls: VideoControls, transfer: str, lock: threading.RLock,
                 now_ns: Callable[[], int], sleep: Callable[[float], None], configured: Callable[[], bool]) -> None:
        self.endpoint = endpoint
        self.controls = controls
        self.transfer = transfer
        self.realtime = endpoint.realtime
        self.bus = BusSchedule()
        self._lock = lock
        self._now_ns = now_ns
        self._sleep = sleep
        self._configured = configured

    @property
    def active(self) -> bool:
        """Whether the stream is running."""
        return self.endpoint.active

    def start(self, payload_size: int, service_interval_ns: int | None = None) -> None:
        """Start the committed stream in payloads of ``payload_size`` bytes (an isochronous one on a bus served
        every ``service_interval_ns``)."""
        if service_interval_ns is not None:
            self.bus = BusSchedule(service_interval_ns)
        self.endpoint.start(self.controls.committed, payload_size)
        self.controls.streaming = True

    def stop(self) -> None:
        """Stop the stream (a frame cut short counts as aborted)."""
        self.endpoint.stop()
        self.controls.streaming = False

    def read(self, endpoint: int, max_len: int, timeout_ms: int | None = None) -> bytes:
        """One isochronous packet (a whole payload; b'' when nothing is due), or one bulk transfer (the payload
        stream's next ``max_len`` bytes at most, see ``StreamEndpoint.next_bulk``). A bulk read waits for the
        next frame up to ``timeout_ms`` (None or 0: forever), on the device clock."""
        deadline = Deadline(timeout_ms / 1000 if timeout_ms else None, self._clock_s)
        while True:
            got = self._try_read(endpoint, max_len)
            if self.transfer == "iso":  # one packet, with or without data, per service interval
                self._bus_time(1)
                return got if isinstance(got, bytes) else b""
            if isinstance(got, bytes):
                return got
            left = deadline.remaining()
            if left is not None and got / 1e9 > left:
                self._sleep(left)
                raise TransferTimeout(f"no frame within {timeout_ms} ms")
            self._sleep(got / 1e9)

    def read_packets(self, endpoint: int, n_packets: int, max_len: int) -> tuple[bytes, list[int], list[int]]:
        """An isochronous URB's worth of packets: their data back to back, their lengths and statuses (0 or
        -errno). Packets for which no frame is due yet are zero-length; in real-time mode every packet takes
        its service interval."""
        if self.transfer != "iso":
            raise Stall("packets are read from an isochronous endpoint", C.ERR_INVALID_REQUEST)
        with self._lock:
            self._check_stream(endpoint)
            data, lengths, status, _wait_ns = self.endpoint.next_payloads(n_packets, max_len)
        self._bus_time(n_packets)
        pad = [0] * (n_packets - len(lengths))
        return data, lengths + pad, status + pad

    def _clock_s(self) -> float:
        return self._now_ns() / 1e9

    def _bus_time(self, n_packets: int) -> None:
        """Real-time mode: wait (on the device clock) until ``n_packets`` more packets have had their service
        intervals on the bus."""
        if not self.realtime:
            return
        now = self._now_ns()
        end = self.bus.book(n_packets, now)
        if end > now:
            self._sleep((end - now) / 1e9)

    def _check_stream(self, endpoint: int) -> None:
        if endpoint != STREAM_EP:
            raise Stall(f"endpoint {endpoint:#04x} is not an IN endpoint of this device", C.ERR_INVALID_UNIT)
        committed = self.controls.committed
        if self.transfer == "bulk" and not self.active and committed is not None and self._configured():
            self.start(committed.payload_size)
        if not self.active:
            raise Stall("the streaming endpoint is not active (commit, then select an alternate setting)",
                        C.ERR_WRONG_STATE)

    def _try_read(self, endpoint: int, max_len: int) -> bytes | int:
        """The next payload, or the ns until the next frame is due."""
        with self._lock:
            self._check_stream(endpoint)
            if self.transfer == "bulk":
                return self.endpoint.next_bulk(max_len)
            return self.endpoint.next_payload(max_len)
