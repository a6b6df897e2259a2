"""The URB phase of one imported USB/IP connection: a reader and two in-order workers, with bounded queues.

After OP_REP_IMPORT a connection carries CMD_SUBMIT / CMD_UNLINK. The reader (the connection's own thread)
decodes them and queues each URB for one of two workers, one for endpoint 0 and one for the streaming
endpoint, so control requests are not held behind reads waiting for a frame. What an importer may hold is
bounded: at most ``max_queued_urbs`` URBs and ``max_urb_bytes`` transfer bytes queued or running (one URB
is always admitted, so the bound is the budget plus one ``MAX_TRANSFER``); beyond that the reader stops
reading and TCP pushes back on the client. Failures follow the Linux stub driver: a failed isochronous URB
still carries one packet descriptor per packet (each with the error and ``actual_length`` 0), as
vhci-hcd reads ``number_of_packets`` descriptors after every isochronous RET_SUBMIT. A CMD_UNLINK of a URB still
queued cancels it at once (RET_UNLINK -ECONNRESET); of a URB a worker is running, it ends that URB early and
its worker answers with the RET_UNLINK in place of the RET_SUBMIT, as the stub driver's completion handler does:
vhci-hcd has given the URB back already, and a RET_SUBMIT for it would make it drop the device. A URB already
answered gets RET_UNLINK 0, always after its RET_SUBMIT (both are sent under one lock). vhci-hcd can send a
CMD_UNLINK ahead of the CMD_SUBMIT it cancels (its sender drains the unlink list after the submit list, so a URB
submitted and unlinked between the two is unlinked first); Linux's stub answers such an unlink 0, runs the URB
when it arrives, and vhci-hcd then drops the device over a reply to a URB it gave back. Here an unlink of a
seqnum newer than every URB received waits for that URB, which is then answered by the RET_UNLINK alone
(-ECONNRESET), never run. A device that is
unplugged (an injected disconnect) ends the connection without answering, as the stub driver's unplug does:
vhci-hcd then gives the outstanding URBs back with -ENODEV and the port goes away.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import threading
import time
from collections import deque
from collections.abc import Callable

from rollcam.common.errors import DeviceError
from rollcam.common.lifecycle import Worker
from rollcam.emu.uvc.device import Setup, UVCFunction
from rollcam.emu.uvc.faults import Disconnected
from rollcam.emu.uvc.requests import Stall
from rollcam.emu.uvc.stream import TransferOverflow, TransferTimeout

from . import protocol as P

log = logging.getLogger("rollcam.usbip")

POLL_MS = 20  # how often a blocked bulk read looks whether the connection closes or its URB was unlinked


def failed(urb: P.Submit, status: int) -> P.RetSubmit:
    """The RET_SUBMIT of a URB that failed with ``status`` (-errno): an isochronous one carries one
    descriptor per packet, each failed and empty, and counts them all in ``error_count``."""
    if not urb.is_iso:
        return P.RetSubmit(urb.seqnum, status, number_of_packets=urb.number_of_packets)
    packets = tuple(P.IsoPacket(p.offset, p.length, 0, status) for p in urb.iso)
    return P.RetSubmit(urb.seqnum, status, 0, 0, len(packets), len(packets), b"", packets)


class UrbSession:
    """Runs the URBs of one importer of ``function`` (``devid``) until the peer leaves or ``abort()``.

    ``recv_command()`` returns the next decoded command (blocking; it raises when the connection ends),
    ``send(data)`` writes a reply, ``abort()`` breaks the connection (a worker that cannot send calls it).
    ``idle_s()`` is how long the importer has had nothing queued or running and sent nothing.
    """

    def __init__(self, function: UVCFunction, devid: int, recv_command: Callable[[], P.Submit | P.Unlink],
                 send: Callable[[bytes], None], abort: Callable[[], None], *, max_queued_urbs: int,
                 max_urb_bytes: int, stats: object) -> None:
        self.function, self.devid = function, devid
        self._recv_command, self._send, self.abort = recv_command, send, abort
        self.max_queued_urbs, self.max_urb_bytes = max_queued_urbs, max_urb_bytes
        self.stats = stats
        self.queues: tuple[deque[P.Submit], deque[P.Submit]] = (deque(), deque())
        self.cond = threading.Condition()
        self.send_lock = threading.Lock()
        self.done = False
        self.frame_number = 0
        self.urbs_received = 0
        self.reserved_bytes = 0  # transfer bytes of URBs queued or running
        self.peak_reserved_bytes = 0
        self._running: dict[int, int | None] = {}  # seqnum of a URB a worker runs -> seqnum of its CMD_UNLINK
        self._unlinked_ahead: dict[int, int] = {}  # seqnum of a URB not received yet -> seqnum of its CMD_UNLINK
        self._newest_submit: int | None = None  # seqnum of the last CMD_SUBMIT received (the reader's own)
        self._last_activity = time.monotonic()

    # ------------------------------------------------------------------------------------------ state
    def idle_s(self) -> float:
        """Seconds since the importer last sent a URB or had one answered; 0 while one is queued or running."""
        with self.cond:
            if self._running or any(self.queues):
                return 0.0
            return time.monotonic() - self._last_activity

    def send(self, data: bytes) -> None:
        with self.send_lock:
            self._send(data)

    def unlinked(self, seqnum: int) -> bool:
        """Whether the running URB ``seqnum`` has been unlinked by the importer (its worker should give up)."""
        with self.cond:
            return self._running.get(seqnum) is not None

    # ------------------------------------------------------------------------------------------ reader
    def run(self) -> None:
        """Read and queue URBs until the connection ends (the exception that ended it propagates)."""
        with contextlib.ExitStack() as workers:  # on the way out: each worker joined, and its error raised
            for q in self.queues:
                workers.enter_context(Worker(self._work, q, name="usbip-urbs", join_timeout_s=5))
            try:
                while True:
                    cmd = self._recv_command()
                    self.urbs_received += 1
                    if isinstance(cmd, P.Unlink):
                        self._unlink(cmd)
                        continue
                    self._newest_submit = cmd.seqnum
                    unlink = self._unlinked_ahead.pop(cmd.seqnum, None)
                    if unlink is not None:  # unlinked before it came: answered, never run
                        log.debug("URB %d arrived after its unlink %d: answered by the RET_UNLINK", cmd.seqnum,
                                  unlink)
                        self.stats.unlinked += 1
                        self.send(P.RetUnlink(unlink, -errno.ECONNRESET).pack())
                        continue
                    self._enqueue(cmd)
            finally:
                with self.cond:
                    self.done = True
                    self.cond.notify_all()

    def _enqueue(self, cmd: P.Submit) -> None:
        cost = cmd.transfer_buffer_length
        with self.cond:
            self._last_activity = time.monotonic()
            while not self.done and (sum(map(len, self.queues)) >= self.max_queued_urbs
                                     or (self.reserved_bytes and self.reserved_bytes + cost > self.max_urb_bytes)):
                self.cond.wait(0.5)  # back-pressure: the client's sends wait in TCP, not in our memory
            if self.done:
                return
            self.reserved_bytes += cost
            self.peak_reserved_bytes = max(self.peak_reserved_bytes, self.reserved_bytes)
            self.queues[cmd.ep != 0].append(cmd)
            self.cond.notify_all()

    def _unlink(self, cmd: P.Unlink) -> None:
        # send_lock before cond, as in _answer: a worker's RET_SUBMIT and this RET_UNLINK never cross.
        with self.send_lock:
            with self.cond:
                target = cmd.unlink_seqnum
                hit = next((u for q in self.queues for u in q if u.seqnum == target), None)
                if hit is not None:
                    self.queues[hit.ep != 0].remove(hit)
                    self.reserved_bytes -= hit.transfer_buffer_length
                    self.stats.unlinked += 1
                    self.cond.notify_all()
                elif target in self._running:
                    self._running[target] = cmd.seqnum  # its worker answers, with this RET_UNLINK
                    return
                elif self._not_received_yet(target) and len(self._unlinked_ahead) < self.max_queued_urbs:
                    log.debug("unlink %d of URB %d, which has not arrived yet: answered when it does",
                              cmd.seqnum, target)
                    self._unlinked_ahead[target] = cmd.seqnum
                    return
            self._send(P.RetUnlink(cmd.seqnum, -errno.ECONNRESET if hit else 0).pack())

    def _not_received_yet(self, seqnum: int) -> bool:
        """Whether URB ``seqnum`` is newer than every CMD_SUBMIT received (vhci-hcd numbers its commands from one
        32-bit counter, in order; a difference of less than half the range is taken as ahead)."""
        newest = self._newest_submit
        return newest is None or 0 < (seqnum - newest) % 2**32 < 2**31

    # ------------------------------------------------------------------------------------------ workers
    def _work(self, queue: deque[P.Submit]) -> None:
        while True:
            with self.cond:
                while not queue and not self.done:
                    self.cond.wait()
                if self.done:
                    return
                urb = queue.popleft()
                self._running[urb.seqnum] = None
                self.cond.notify_all()
            try:
                self._answer(urb, self.execute(urb))
            except Disconnected:
                self.abort()  # the device is gone: the connection ends, unanswered (the stub's unplug)
                return
            except OSError as exc:
                log.warning("USB/IP importer of device %d did not take a reply (%s): connection closed",
                            self.devid, exc)
                self.abort()  # a peer that does not take its replies loses the connection, not just a worker
                return
            finally:
                with self.cond:
                    self._running.pop(urb.seqnum, None)
                    self.reserved_bytes -= urb.transfer_buffer_length
                    self._last_activity = time.monotonic()
                    self.cond.notify_all()
            self.stats.urbs += 1

    def _answer(self, urb: P.Submit, reply: P.RetSubmit) -> None:
        """Send ``reply``, or the RET_UNLINK that replaces it when the importer unlinked ``urb`` meanwhile."""
        with self.send_lock:
            with self.cond:
                unlink = self._running.pop(urb.seqnum, None)
                if unlink is not None:
                    self.stats.unlinked += 1
            if unlink is None:
                self._send(reply.pack())
            else:
                self._send(P.RetUnlink(unlink, -errno.ECONNRESET).pack())

    def execute(self, urb: P.Submit) -> P.RetSubmit:
        """Run one URB against the device; USB errors become negative errno statuses."""
        fn = self.function
        if urb.devid != self.devid:
            return failed(urb, -errno.ENODEV)
        try:
            if urb.ep == 0:
                setup = Setup.unpack(urb.setup)
                data = fn.control(setup, urb.data)
                actual = len(data) if setup.is_in else len(urb.data)
                return P.RetSubmit(urb.seqnum, 0, actual, number_of_packets=urb.number_of_packets, data=data)
            if urb.direction != P.DIR_IN:
                return failed(urb, -errno.EPIPE)
            if urb.is_iso:
                return self._iso(urb)
            data = self._bulk(urb)
            return P.RetSubmit(urb.seqnum, 0, len(data), number_of_packets=urb.number_of_packets, data=data)
        except Stall:
            return failed(urb, -errno.EPIPE)
        except TransferOverflow:
            return failed(urb, -errno.EOVERFLOW)
        except Disconnected:
            raise
        except DeviceError:
            return failed(urb, -errno.ESHUTDOWN)
        except Exception:  # a fault of the emulated function: answer the URB so the importer stays in step
            log.exception("URB %d on endpoint %d failed in the emulated device", urb.seqnum, urb.ep)
            return failed(urb, -errno.EPROTO)

    def _bulk(self, urb: P.Submit) -> bytes:
        while True:
            if self.done:
                raise DeviceError("connection closing")
            if self.unlinked(urb.seqnum):
                raise DeviceError(f"URB {urb.seqnum} unlinked")  # answered by its RET_UNLINK
            try:
                return self.function.read(0x80 | urb.ep, urb.transfer_buffer_length, POLL_MS)
            except TransferTimeout:
                continue

    def _iso(self, urb: P.Submit) -> P.RetSubmit:
        n = len(urb.iso)
        size = min((p.length for p in urb.iso), default=0)
        try:
            data, lengths, status = self.function.read_packets(0x80 | urb.ep, n, size)
        except TransferOverflow:
            data, lengths, status = b"", [0] * n, [-errno.EOVERFLOW] * n
        packets = tuple(P.IsoPacket(p.offset, p.length, k, st)
                        for p, k, st in zip(urb.iso, lengths, status, strict=True))
        start = self.frame_number
        self.frame_number = (self.frame_number + n) & 0x3FFF
        return P.RetSubmit(urb.seqnum, 0, len(data), start, n, sum(st != 0 for st in status), data, packets)
