"""A pyusb backend (``usb.backend.IBackend``) whose bus holds emulated UVC functions.

``usb.core.find(idVendor=..., backend=EmulatedBackend([function]))`` finds the camera; descriptors, configuration,
control transfers (probe/commit, camera controls), ``set_interface_altsetting`` and reads from the streaming
endpoint then go to the ``UVCFunction`` as they would go through libusb to a real camera. A STALL reaches the
caller as ``usb.core.USBError`` with errno EPIPE, a timeout as ``usb.core.USBTimeoutError``, an overflow
(babble) with EOVERFLOW, as libusb reports them. An isochronous read returns one packet (one payload or a
zero-length packet) per call. A function that was unplugged (an injected disconnect) fails every call on
its open handles with ENODEV (libusb's LIBUSB_ERROR_NO_DEVICE); the next enumeration (``usb.core.find``)
finds it again at a new address, as a bus re-enumerates a camera plugged back in.
"""

from __future__ import annotations

import errno
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from types import SimpleNamespace

from rollcam.common.errors import SourceError, require

from . import constants as C
from .descriptors import split_descriptors
from .device import Setup, UVCFunction
from .faults import Disconnected
from .requests import Stall
from .stream import TransferOverflow, TransferTimeout

require("usb.core", "pyusb", feature="the emulated USB backend")
import usb.backend  # noqa: E402
import usb.core  # noqa: E402

_DEVICE_FIELDS = ("bLength", "bDescriptorType", "bcdUSB", "bDeviceClass", "bDeviceSubClass", "bDeviceProtocol",
                  "bMaxPacketSize0", "idVendor", "idProduct", "bcdDevice", "iManufacturer", "iProduct",
                  "iSerialNumber", "bNumConfigurations")
_CONFIG_FIELDS = ("bLength", "bDescriptorType", "wTotalLength", "bNumInterfaces", "bConfigurationValue",
                  "iConfiguration", "bmAttributes", "bMaxPower")
_INTF_FIELDS = ("bLength", "bDescriptorType", "bInterfaceNumber", "bAlternateSetting", "bNumEndpoints",
                "bInterfaceClass", "bInterfaceSubClass", "bInterfaceProtocol", "iInterface")
_EP_FIELDS = ("bLength", "bDescriptorType", "bEndpointAddress", "bmAttributes", "wMaxPacketSize", "bInterval")


def _fields(names: tuple[str, ...], fmt: str, raw: bytes, extra: bytes = b"", **more: object) -> SimpleNamespace:
    values = struct.unpack_from(fmt, raw)
    return SimpleNamespace(**dict(zip(names, values, strict=True)), extra_descriptors=list(extra), **more)


@dataclass
class ConfigTree:
    """A configuration descriptor split the way libusb reports it: class-specific descriptors as ``extra``."""

    config: SimpleNamespace
    interfaces: list[list[SimpleNamespace]] = field(default_factory=list)  # [interface index][alt index]
    endpoints: dict[tuple[int, int], list[SimpleNamespace]] = field(default_factory=dict)


def parse_config_tree(blob: bytes) -> ConfigTree:
    """Split a configuration blob into config, interfaces by alternate setting and their endpoints."""
    parts = split_descriptors(blob)
    tree: ConfigTree | None = None
    extra = bytearray()
    target: SimpleNamespace | None = None
    by_number: dict[int, int] = {}
    key = (0, 0)

    def flush() -> None:
        if target is not None:
            target.extra_descriptors = list(bytes(extra))
        extra.clear()

    for d in parts:
        if d[1] == C.DT_CONFIGURATION and tree is None:
            tree = ConfigTree(_fields(_CONFIG_FIELDS, "<BBHBBBBB", d))
            target = tree.config
        elif d[1] == C.DT_INTERFACE and tree is not None:
            flush()
            target = _fields(_INTF_FIELDS, "<BBBBBBBBB", d)
            i = by_number.setdefault(target.bInterfaceNumber, len(tree.interfaces))
            if i == len(tree.interfaces):
                tree.interfaces.append([])
            key = (i, len(tree.interfaces[i]))
            tree.interfaces[i].append(target)
            tree.endpoints[key] = []
        elif d[1] == C.DT_ENDPOINT and tree is not None and tree.interfaces:
            flush()
            target = _fields(_EP_FIELDS, "<BBBBHB", d, bRefresh=0, bSynchAddress=0)
            tree.endpoints[key].append(target)
        else:
            extra.extend(d)
    flush()
    if tree is None:
        raise SourceError("configuration blob has no configuration descriptor")
    return tree


@dataclass
class _Dev:
    function: UVCFunction
    bus: int
    address: int
    tree: ConfigTree


@dataclass
class _Handle:
    dev: _Dev
    claimed: set[int] = field(default_factory=set)
    generation: int = 0  # the function's plug-in this handle was opened on


def _usb_error(exc: Exception) -> usb.core.USBError:
    if isinstance(exc, Disconnected):
        return usb.core.USBError(f"No such device (it may have been disconnected): {exc}", -4, errno.ENODEV)
    if isinstance(exc, TransferTimeout):
        return usb.core.USBTimeoutError(str(exc), -7, errno.ETIMEDOUT)
    if isinstance(exc, TransferOverflow):
        return usb.core.USBError(str(exc), -8, errno.EOVERFLOW)
    return usb.core.USBError(f"Pipe error: {exc}", -9, errno.EPIPE)


class EmulatedBackend(usb.backend.IBackend):
    """A pyusb backend for a bus of emulated UVC functions (bus ``bus``, addresses 1, 2, ...)."""

    def __init__(self, functions: Sequence[UVCFunction], bus: int = 1) -> None:
        super().__init__()
        self.devices = [_Dev(f, bus, i, parse_config_tree(f.descriptors.configuration))
                        for i, f in enumerate(functions, 1)]

    def enumerate_devices(self):
        for d in self.devices:
            if d.function.plug.disconnected:  # plugged back in: the bus gives it the next free address
                d.function.reset()
                d.address = max(x.address for x in self.devices) + 1
        return iter(self.devices)

    def get_parent(self, dev):
        return None

    def get_device_descriptor(self, dev):
        return _fields(_DEVICE_FIELDS, "<BBHBBBBHHHBBBB", dev.function.descriptors.device, bus=dev.bus,
                       address=dev.address, port_number=dev.address, port_numbers=(dev.address,),
                       speed=C.SPEED_HIGH)

    def get_configuration_descriptor(self, dev, config):
        if config != 0:
            raise IndexError(config)
        return dev.tree.config

    def get_interface_descriptor(self, dev, intf, alt, config):
        if config != 0:
            raise IndexError(config)
        return dev.tree.interfaces[intf][alt]

    def get_endpoint_descriptor(self, dev, ep, intf, alt, config):
        if config != 0:
            raise IndexError(config)
        return dev.tree.endpoints[(intf, alt)][ep]

    def open_device(self, dev):
        return _Handle(dev, generation=dev.function.plug.generation)

    @staticmethod
    def _alive(h: _Handle) -> None:
        plug = h.dev.function.plug
        if plug.disconnected or h.generation != plug.generation:
            raise _usb_error(Disconnected("the handle's device was unplugged"))

    def close_device(self, dev_handle):
        dev_handle.claimed.clear()

    def _control(self, h: _Handle, setup: Setup, data: bytes = b"") -> bytes:
        self._alive(h)
        try:
            return h.dev.function.control(setup, data)
        except (Stall, Disconnected) as exc:
            raise _usb_error(exc) from None

    def set_configuration(self, dev_handle, config_value):
        self._control(dev_handle, Setup(0x00, C.REQ_SET_CONFIGURATION, config_value, 0, 0))

    def get_configuration(self, dev_handle):
        return self._control(dev_handle, Setup(0x80, C.REQ_GET_CONFIGURATION, 0, 0, 1))[0]

    def set_interface_altsetting(self, dev_handle, intf, altsetting):
        self._control(dev_handle, Setup(0x01, C.REQ_SET_INTERFACE, altsetting, intf, 0))

    def claim_interface(self, dev_handle, intf):
        dev_handle.claimed.add(intf)

    def release_interface(self, dev_handle, intf):
        dev_handle.claimed.discard(intf)

    def _read(self, dev_handle, ep, buff, timeout) -> int:
        self._alive(dev_handle)
        try:
            data = dev_handle.dev.function.read(ep, len(buff) * buff.itemsize, timeout)
        except (Stall, TransferTimeout, TransferOverflow, Disconnected) as exc:
            raise _usb_error(exc) from None
        memoryview(buff).cast("B")[: len(data)] = data
        return len(data)

    def bulk_read(self, dev_handle, ep, intf, buff, timeout):
        return self._read(dev_handle, ep, buff, timeout)

    def iso_read(self, dev_handle, ep, intf, buff, timeout):
        return self._read(dev_handle, ep, buff, timeout)

    def intr_read(self, dev_handle, ep, intf, buff, timeout):
        raise usb.core.USBError("Pipe error: the camera has no interrupt endpoint", -9, errno.EPIPE)

    def bulk_write(self, dev_handle, ep, intf, data, timeout):
        raise usb.core.USBError("Pipe error: the camera has no OUT endpoint", -9, errno.EPIPE)

    iso_write = intr_write = bulk_write

    def ctrl_transfer(self, dev_handle, bmRequestType, bRequest, wValue, wIndex, data, timeout):
        length = len(data) * data.itemsize
        setup = Setup(bmRequestType, bRequest, wValue, wIndex, length)
        if setup.is_in:
            out = self._control(dev_handle, setup)
            memoryview(data).cast("B")[: len(out)] = out
            return len(out)
        self._control(dev_handle, setup, data.tobytes())
        return length

    def clear_halt(self, dev_handle, ep):
        self._control(dev_handle, Setup(0x02, C.REQ_CLEAR_FEATURE, C.FEATURE_ENDPOINT_HALT, ep, 0))

    def reset_device(self, dev_handle):
        self._alive(dev_handle)
        dev_handle.dev.function.reset()

    def is_kernel_driver_active(self, dev_handle, intf):
        return False

    def detach_kernel_driver(self, dev_handle, intf):
        pass

    def attach_kernel_driver(self, dev_handle, intf):
        pass
