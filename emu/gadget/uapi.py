"""The kernel's UVC gadget interface to user space (``linux/usb/g_uvc.h``, Linux 6.1) beside V4L2's own.

The UVC function's V4L2 node (driver ``g_uvc``, an output device) reports the USB side as private V4L2 events;
each event's 64 data bytes are a ``struct uvc_event``: the bus speed (CONNECT), the 8-byte
``struct usb_ctrlrequest`` (SETUP) or a ``struct uvc_request_data`` (DATA: what the host sent in the data stage
of a SET_CUR). User space answers a SETUP with ``UVCIOC_SEND_RESPONSE`` and a ``struct uvc_request_data``:
the reply bytes of an IN request, the length to receive of an OUT one, or a negative length for a STALL. The
V4L2 structures are ``rollcam.emu.v4l2.raw``'s, request numbers ``rollcam.emu.v4l2.abi``'s.
"""

from __future__ import annotations

import ctypes as C

from rollcam.emu.v4l2.raw import Event, EventSubscription

V4L2_EVENT_PRIVATE_START = 0x08000000
UVC_EVENT_CONNECT = V4L2_EVENT_PRIVATE_START + 0
UVC_EVENT_DISCONNECT = V4L2_EVENT_PRIVATE_START + 1
UVC_EVENT_STREAMON = V4L2_EVENT_PRIVATE_START + 2
UVC_EVENT_STREAMOFF = V4L2_EVENT_PRIVATE_START + 3
UVC_EVENT_SETUP = V4L2_EVENT_PRIVATE_START + 4
UVC_EVENT_DATA = V4L2_EVENT_PRIVATE_START + 5
UVC_EVENTS = (UVC_EVENT_CONNECT, UVC_EVENT_DISCONNECT, UVC_EVENT_STREAMON, UVC_EVENT_STREAMOFF, UVC_EVENT_SETUP,
              UVC_EVENT_DATA)
EVENT_NAMES = {UVC_EVENT_CONNECT: "CONNECT", UVC_EVENT_DISCONNECT: "DISCONNECT", UVC_EVENT_STREAMON: "STREAMON",
               UVC_EVENT_STREAMOFF: "STREAMOFF", UVC_EVENT_SETUP: "SETUP", UVC_EVENT_DATA: "DATA"}

UVC_MAX_REQUEST_SIZE = 64
"""The most bytes a SETUP's reply or data stage carries through the function (longer ones it stalls itself)."""

BUF_TYPE_VIDEO_OUTPUT = 2
V4L2_PIX_FMT_YUYV = int.from_bytes(b"YUYV", "little")


class UvcRequestData(C.Structure):
    """``struct uvc_request_data``: ``length`` (negative: STALL) and up to 60 bytes."""

    _fields_ = [("length", C.c_int32), ("data", C.c_uint8 * 60)]


UVCIOC_SEND_RESPONSE = (1 << 30) | (C.sizeof(UvcRequestData) << 16) | (ord("U") << 8) | 1
"""``_IOW('U', 1, struct uvc_request_data)``."""

STALL = -1


def response(data: bytes | None) -> UvcRequestData:
    """The ``UVCIOC_SEND_RESPONSE`` argument for ``data`` (None: a STALL)."""
    out = UvcRequestData(length=STALL if data is None else len(data))
    if data:
        if len(data) > len(out.data):
            raise ValueError(f"a UVC gadget response carries at most {len(out.data)} bytes, not {len(data)}")
        C.memmove(out.data, bytes(data), len(data))
    return out


def event_request(event: Event) -> bytes:
    """The 8-byte ``struct usb_ctrlrequest`` of a SETUP event."""
    return bytes(event.u.data[:8])


def event_data(event: Event) -> bytes:
    """The bytes of a DATA event (the data stage of the pending SET_CUR)."""
    raw = bytes(event.u.data)
    length = int.from_bytes(raw[:4], "little", signed=True)
    return raw[4:4 + max(0, min(length, 60))]


def subscription(event_type: int) -> EventSubscription:
    """The ``VIDIOC_SUBSCRIBE_EVENT`` argument for one UVC event."""
    return EventSubscription(type=event_type)
