"""The gadget's answers to the UVC class requests the kernel passes up as SETUP and DATA events.

``SetupHandler`` is pure: it takes the 8 bytes of a SETUP (and, for a SET_CUR, the bytes of the DATA event
that follows) and returns what to send with ``UVCIOC_SEND_RESPONSE``: the reply of a GET request, the length
to receive of a SET_CUR, or None for a STALL. The answers themselves are ``rollcam.emu.uvc.requests.
VideoControls``' (probe/commit, the camera terminal's and processing unit's controls, the request error code),
the same object the emulated USB camera answers with, over the one ``FirmwareCamera`` (so controls reach
``rollcam.firmware.controls``). A request rollcam does not implement is stalled, as a real device does, and
logged once per kind.

One difference from a device that sees the whole control transfer: Linux's UVC function completes the status
stage of a SET_CUR by itself after its data stage, so a SET_CUR whose data is refused cannot be stalled any
more; it sets the request error code (VC_REQUEST_ERROR_CODE_CONTROL) a host reads after it, as UVC 1.5
section 4.2.1.2 describes. Unknown units and controls are stalled at the SETUP, before any data stage.
"""

from __future__ import annotations

import logging

from rollcam.emu.uvc import Setup, Stall
from rollcam.emu.uvc import constants as C
from rollcam.emu.uvc.requests import SCALARS, UNITS, VideoControls

log = logging.getLogger("rollcam.gadget")


class SetupHandler:
    """Answers one UVC function's class requests from ``controls``; ``interfaces`` are the function's
    VideoControl and VideoStreaming interface numbers as the host sees them (configfs ``bInterfaceNumber``)."""

    def __init__(self, controls: VideoControls, interfaces: tuple[int, int] = (0, 1)) -> None:
        self.controls = controls
        self.interfaces = interfaces
        self.pending: Setup | None = None  # a SET_CUR waiting for its DATA event
        self.stalls = 0
        self.logged: set[tuple] = set()

    def _interface(self, setup: Setup) -> int:
        """The request's interface as ``VideoControls`` numbers them (0 control, 1 streaming)."""
        number = setup.wIndex & 0xFF
        if number not in self.interfaces:
            raise Stall(f"no interface {number} in this function", C.ERR_INVALID_UNIT)
        return self.interfaces.index(number)

    def setup(self, raw: bytes) -> bytes | None:
        """The response to one SETUP: reply bytes (IN), ``wLength`` zero bytes to receive the data stage (a
        SET_CUR, answered at ``data()``), or None to STALL."""
        setup = Setup.unpack(bytes(raw[:8]))
        self.pending = None
        try:
            if setup.bmRequestType & C.TYPE_MASK != C.TYPE_CLASS or \
                    setup.bmRequestType & C.RECIP_MASK != C.RECIP_INTERFACE:
                raise Stall(f"bmRequestType {setup.bmRequestType:#04x} is not a class request to an interface",
                            C.ERR_INVALID_REQUEST)
            if setup.is_in == (setup.bRequest == C.SET_CUR):
                raise Stall(f"request {setup.bRequest:#04x} with direction bit {setup.is_in}", C.ERR_INVALID_REQUEST)
            intf, entity, selector = self._interface(setup), setup.wIndex >> 8, setup.wValue >> 8
            if setup.bRequest == C.SET_CUR:
                self._check_target(intf, entity, selector)
                self.pending = setup
                return bytes(setup.wLength)
            return self.controls.request(setup.bRequest, intf, entity, selector, setup.wLength, b"")[:setup.wLength]
        except Stall as exc:
            self._stalled(setup, exc)
            return None

    def _check_target(self, intf: int, entity: int, selector: int) -> None:
        """Refuse a SET_CUR to a unit or control that does not exist before its data stage (a STALL)."""
        if (intf, entity) not in UNITS:
            raise self._error(Stall(f"no unit {entity} on interface {intf}", C.ERR_INVALID_UNIT))
        streaming = intf == 1 and selector in (C.VS_PROBE_CONTROL, C.VS_COMMIT_CONTROL)
        if streaming:
            return
        control = SCALARS.get((intf, entity, selector))
        if control is None:
            raise self._error(Stall(f"unit {entity} has no control {selector:#04x}", C.ERR_INVALID_CONTROL))
        if control.set is None:
            raise self._error(Stall(f"control {selector:#04x} of unit {entity} is read-only", C.ERR_INVALID_REQUEST))

    def _error(self, exc: Stall) -> Stall:
        self.controls.error_code = exc.code
        return exc

    def data(self, data: bytes) -> None:
        """The data stage of the pending SET_CUR: applied, or refused with the request error code set (the
        status stage is the kernel's, already done)."""
        setup, self.pending = self.pending, None
        if setup is None:
            log.warning("UVC gadget: a DATA event with no SET_CUR before it (%d bytes) ignored", len(data))
            return
        try:
            self.controls.request(C.SET_CUR, self._interface(setup), setup.wIndex >> 8, setup.wValue >> 8,
                                  setup.wLength, bytes(data[:setup.wLength]))
        except Stall as exc:
            self._stalled(setup, exc)

    def _stalled(self, setup: Setup, exc: Stall) -> None:
        self.stalls += 1
        kind = (setup.bmRequestType, setup.bRequest, setup.wValue >> 8, setup.wIndex)
        if kind not in self.logged:
            self.logged.add(kind)
            name = C.REQUEST_NAMES.get(setup.bRequest, f"request {setup.bRequest:#04x}")
            log.warning("UVC gadget: %s selector %#04x wIndex %#06x refused: %s (logged once)", name,
                     setup.wValue >> 8, setup.wIndex, exc)
