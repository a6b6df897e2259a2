"""What cameras this machine has, per backend, for ``rollcam list``: each section says why it is empty.

Every ``*_devices`` function returns ``(rows, note)``: the devices found as plain dicts, and a note that
explains an empty list (the backend is missing, the platform lacks it, or nothing is plugged in). Backends
are passed in where tests need a seam (``dai``, ``usb_find``); by default they are imported lazily.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rollcam.common.errors import MissingDependencyError, require

Rows = list[dict[str, Any]]
USB_VIDEO_CLASS = 0x0E


def v4l2_devices(dev: Path = Path("/dev"), sysfs: Path = Path("/sys/class/video4linux")) -> tuple[Rows, str]:
    """``/dev/videoN`` nodes with their driver names (Linux)."""
    if not sys.platform.startswith("linux"):
        return [], f"V4L2 exists only on Linux (this is {sys.platform}); use opencv:N"
    rows = []
    for node in sorted(dev.glob("video*"), key=lambda p: (len(p.name), p.name)):
        name_file = sysfs / node.name / "name"
        name = name_file.read_text().strip() if name_file.is_file() else ""
        rows.append({"uri": f"v4l2:{node}", "path": str(node), "name": name})
    return rows, "" if rows else f"no {dev}/video* nodes: no camera plugged in, or its driver is not loaded"


def oak_devices(dai: Any = None) -> tuple[Rows, str]:
    """OAK cameras depthai can see."""
    if dai is None:
        from .oak import import_depthai

        try:
            dai = import_depthai()
        except MissingDependencyError as exc:
            return [], str(exc)
    try:
        infos = dai.Device.getAllAvailableDevices()
    except RuntimeError as exc:
        return [], f"depthai cannot search for devices ({exc})"
    rows = [{"uri": f"oak:{d.getDeviceId()}", "id": d.getDeviceId(), "name": str(getattr(d, "name", "")),
             "state": str(getattr(d, "state", ""))} for d in infos]
    return rows, "" if rows else "no OAK found: plug one in (USB3), or put a PoE model on this network"


def usb_video_devices(usb_find: Callable[..., Any] | None = None) -> tuple[Rows, str]:
    """USB devices with a video-class interface (UVC cameras), through pyusb."""
    if usb_find is None:
        try:
            usb_find = require("usb.core", "pyusb", feature="USB discovery").find
        except MissingDependencyError as exc:
            return [], f"{exc}; real cameras also need libusb-1.0 from the OS"
    try:
        devices = list(usb_find(find_all=True))
    except Exception as exc:  # pyusb's NoBackendError and libusb access errors
        kind = type(exc).__name__
        hint = "install libusb-1.0 (e.g. apt install libusb-1.0-0)" if kind == "NoBackendError" else str(exc)
        return [], f"pyusb cannot reach USB ({kind}): {hint}"
    rows = []
    for d in devices:
        classes = {getattr(i, "bInterfaceClass", None) for cfg in d for i in cfg}
        if USB_VIDEO_CLASS in classes or getattr(d, "bDeviceClass", None) == USB_VIDEO_CLASS:
            vid, pid = int(d.idVendor), int(d.idProduct)
            rows.append({"uri": f"uvc:{vid:04x}:{pid:04x}", "vid": f"{vid:04x}", "pid": f"{pid:04x}",
                         "bus": getattr(d, "bus", None), "address": getattr(d, "address", None)})
    return rows, "" if rows else "no USB video-class device attached"


SECTIONS: dict[str, tuple[str, Callable[[], tuple[Rows, str]]]] = {
    "v4l2": ("V4L2 devices", v4l2_devices),
    "oak": ("OAK devices (depthai)", oak_devices),
    "usb": ("USB video devices (pyusb)", usb_video_devices),
}
"""JSON key -> (heading, discovery function) of the device sections of ``rollcam list``."""


def discover() -> dict[str, dict[str, Any]]:
    """Every device section as ``{key: {"devices": rows, "note": note}}``."""
    out = {}
    for key, (_, find) in SECTIONS.items():
        rows, note = find()
        out[key] = {"devices": rows, "note": note}
    return out
