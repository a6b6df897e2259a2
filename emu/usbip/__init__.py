"""USB/IP for the emulated cameras: the wire codec (``protocol``), a server that Linux's ``usbip attach`` can
import a camera from (``server``), and a client for tests and the ``uvc:`` source (``client``)."""

from __future__ import annotations

from .client import ImportedDevice, UrbError, list_devices
from .protocol import ExportedDevice
from .server import DEFAULT_PORT, USBIPServer, describe, usbip_commands

__all__ = ["DEFAULT_PORT", "ExportedDevice", "ImportedDevice", "USBIPServer", "UrbError", "describe",
           "list_devices", "usbip_commands"]
