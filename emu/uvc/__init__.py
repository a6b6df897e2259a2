"""USB Video Class 1.5 for the emulated camera, in layers: constants, then pure codecs (``descriptors``,
``probe``, ``payload``, ``convert``), then the USB function (``requests``, ``device``) over a ``FrameProducer``,
then the transports that drive it (``pyusb_backend`` here, ``rollcam.emu.usbip`` over TCP).

Typical use::

    camera = FirmwareCamera("imx219", scene="street", size=(640, 480))   # rollcam.firmware.camera
    function = UVCFunction(FirmwareProducer(camera))  # iso by default; transfer="bulk" for a bulk camera
    dev = usb.core.find(idVendor=0x1209, idProduct=0x0001, backend=EmulatedBackend([function]))
"""

from __future__ import annotations

from .descriptors import (
    DescriptorSet,
    DeviceIdentity,
    FrameSize,
    StreamFormat,
    build_descriptors,
    frame_rates,
    parse_streaming,
)
from .device import Intervals, Setup, UVCFunction, iso_payload_size, offered_formats
from .faults import Disconnected
from .firmware_producer import FirmwareProducer
from .payload import ParsedFrame, PayloadBatch, PayloadPacker, PayloadParser, pack_header, parse_header
from .probe import Probe
from .producer import ControlRange, FrameProducer, offered_intervals_ns
from .requests import Stall
from .stream import StreamStats, TransferOverflow, TransferTimeout

__all__ = [
    "ControlRange",
    "DescriptorSet",
    "DeviceIdentity",
    "Disconnected",
    "FirmwareProducer",
    "FrameProducer",
    "FrameSize",
    "Intervals",
    "ParsedFrame",
    "PayloadBatch",
    "PayloadPacker",
    "PayloadParser",
    "Probe",
    "Setup",
    "Stall",
    "StreamFormat",
    "StreamStats",
    "TransferOverflow",
    "TransferTimeout",
    "UVCFunction",
    "build_descriptors",
    "frame_rates",
    "iso_payload_size",
    "offered_formats",
    "offered_intervals_ns",
    "pack_header",
    "parse_header",
    "parse_streaming",
]
