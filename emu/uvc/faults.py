"""Faults of the UVC function's streaming endpoint, as a real USB camera's show on the bus.

``PayloadFaults`` applies a ``rollcam.common.faults.FaultPlan`` to each payload the endpoint sends, decided by
the payload's index in the stream (so the same plan hits the same payloads whatever the host's timing):

- ``babble``: the device sends more than the host asked for; the payload is lost and the transfer (or the
  isochronous packet) ends in an overflow: ``TransferOverflow``, EOVERFLOW to pyusb and USB/IP.
- ``short``: the payload is cut short after its header (a short packet, a short bulk transfer); the host
  gets fewer bytes than the frame needs.
- ``stall`` (bulk endpoints only; USB 2.0 gives isochronous endpoints no handshake): the endpoint halts with
  a STALL (EPIPE) and stays halted, every transfer stalling, until the host clears the halt
  (CLEAR_FEATURE(ENDPOINT_HALT), which also ends a UVC bulk stream).

The frames these faults leave incomplete are counted once each in ``stats.damaged_frames``. Frame-level faults
(``drop``, ``error``, ``disconnect``) are the endpoint's (``stream.StreamEndpoint``), control-request stalls
the function's.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator

from rollcam.common.errors import DeviceError
from rollcam.common.faults import FaultInjector

from . import constants as C
from .requests import Stall

HEADER_LEN = 12  # every payload this device sends carries the full 12-byte header


class TransferOverflow(DeviceError):
    """The host's buffer is smaller than the payload the device has to send (a babble/overflow error)."""


class Disconnected(DeviceError):
    """The device went away (an injected unplug): every transfer fails until the host enumerates it again."""


class Plug:
    """Whether a USB function is plugged in: ``disconnected`` after an injected unplug, ``generation`` counting
    the plug-ins since (a host handle opened on an older one is dead)."""

    def __init__(self) -> None:
        self.disconnected = False
        self.generation = 0

    def check(self) -> None:
        """Raise ``Disconnected`` while unplugged."""
        if self.disconnected:
            raise Disconnected("the device was unplugged (injected disconnect); enumerate it again")

    def replug(self) -> None:
        """The host enumerates the device again: plugged in, one generation on."""
        if self.disconnected:
            self.disconnected = False
            self.generation += 1

    @contextlib.contextmanager
    def watch(self, on_unplug: Callable[[], None]) -> Iterator[None]:
        """Run a transfer: refused while unplugged; a ``Disconnected`` from it unplugs (``on_unplug`` runs)."""
        self.check()
        try:
            yield
        except Disconnected:
            self.disconnected = True
            on_unplug()
            raise


class PayloadFaults:
    """Per-payload faults of one streaming endpoint (not thread-safe: the function serialises calls)."""

    def __init__(self, injector: FaultInjector, bulk: bool) -> None:
        self.injector = injector
        self.bulk = bulk
        self.halted = False
        self.index = 0  # payloads offered to the host so far (the event index of every payload fault)
        self._damaged_frame: int | None = None

    @property
    def active(self) -> bool:
        """Whether any payload fault is planned (the endpoint takes its fast path otherwise)."""
        plan = self.injector.plan
        return bool(plan.rate("babble") or plan.rate("short") or (self.bulk and plan.rate("stall")))

    def clear_halt(self) -> None:
        """CLEAR_FEATURE(ENDPOINT_HALT): the endpoint takes transfers again."""
        self.halted = False

    def check_halt(self) -> None:
        """Raise the STALL of a halted endpoint."""
        if self.halted:
            raise Stall("the streaming endpoint is halted (injected STALL; clear the halt)", C.ERR_WRONG_STATE)

    def apply(self, payload: memoryview, frame: int) -> bytes:
        """The bytes that reach the host for ``payload`` of frame ``frame``; raises Stall or TransferOverflow
        for a payload that fails. Call once per payload, in order."""
        k = self.index
        self.index += 1
        inj = self.injector
        if self.bulk and inj.hit("stall", k):
            self.halted = True
            raise Stall(f"injected STALL on payload {k}", C.ERR_WRONG_STATE)
        if inj.hit("babble", k):
            self._damage(frame)
            raise TransferOverflow(f"injected babble on payload {k}")
        if len(payload) > HEADER_LEN and inj.hit("short", k):
            self._damage(frame)
            keep = HEADER_LEN + inj.plan.pick("short", k, len(payload) - HEADER_LEN)
            return bytes(payload[:keep])
        return bytes(payload)

    def _damage(self, frame: int) -> None:
        if self._damaged_frame != frame:
            self._damaged_frame = frame
            self.injector.stats.damaged_frames += 1
