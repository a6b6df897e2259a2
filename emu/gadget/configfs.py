"""The kernel's UVC gadget function configured through configfs, from the one camera's formats.

``layout`` is a pure function: the camera's formats (``rollcam.emu.uvc.offered_formats``, the same tables the
emulated USB camera's descriptors are built from), its identity and the endpoint's packet size become an ordered
list of ``Step`` (make a folder, write an attribute, link), relative to the ``usb_gadget`` folder of configfs.
``Gadget`` applies them with an ``Tree`` (the file system, passed in), binds the gadget to a USB device
controller (UDC), and takes it all down in reverse order: after an error half-way through, and on ``close()``,
nothing it made is left behind.

The tree is that of Linux 6.1's ``usb_f_uvc`` (Documentation/ABI/testing/configfs-usb-gadget-uvc):
``functions/uvc.N/control/header/h`` linked from ``control/class/{fs,ss}``; one folder per format under
``streaming/uncompressed`` (with ``guidFormat`` and ``bBitsPerPixel``) or ``streaming/mjpeg``, one per frame
size inside it (``wWidth``, ``wHeight``, ``dwMinBitRate``, ``dwMaxBitRate``, ``dwMaxVideoFrameBufferSize``,
``dwDefaultFrameInterval``, ``dwFrameInterval``), linked from ``streaming/header/h``, itself linked from
``streaming/class/{fs,hs,ss}``. configfs resolves link targets from the current folder: targets are absolute.
"""

from __future__ import annotations

import errno
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from rollcam.common.errors import DeviceError
from rollcam.common.lifecycle import Closeable
from rollcam.emu.uvc import DeviceIdentity, StreamFormat, frame_rates
from rollcam.emu.uvc.descriptors import FORMATS

CONFIGFS = Path("/sys/kernel/config/usb_gadget")
UDC_CLASS = Path("/sys/class/udc")
FUNCTION = "functions/uvc.0"
CONFIG = "configs/c.1"
LANG = "0x409"  # US English string tables
MAX_PACKET = 3072
"""``streaming_maxpacket``: bytes per (micro)frame of the isochronous endpoint (1024 x 3 transactions at high
speed: the most a high-speed isochronous endpoint carries)."""
FORMAT_DIRS = {"MJPG": "mjpeg"}  # every other wire format is uncompressed
FUNCTION_NAME = "RS"
"""The function's iFunction string. uvcvideo names a camera "PRODUCT: FUNCTION" in 32 bytes (with its NUL);
the function always has one (6.1's default "UVC Camera" makes "rollcam emulated UVC camera: UV"), so a short
one keeps the name whole: "rollcam emulated UVC camera: RS"."""


class GadgetError(DeviceError):
    """The UVC gadget could not be configured, bound or taken down (the message names what is missing)."""


@dataclass(frozen=True)
class Step:
    """One configfs action: ``mkdir`` a folder, ``write`` an attribute, ``link`` (``value`` is the target,
    relative to the same root), or ``bind`` (write the UDC's name to the gadget's ``UDC``)."""

    kind: str
    path: str
    value: str | bytes = ""


def _format_dir(fourcc: str) -> str:
    return f"{FUNCTION}/streaming/{FORMAT_DIRS.get(fourcc, 'uncompressed')}/{fourcc.lower()}"


def layout(formats: Sequence[StreamFormat], identity: DeviceIdentity | None = None, *, gadget: str = "rollcam",
           udc: str | None = None, max_packet: int = MAX_PACKET, interval: int = 1,
           max_power_ma: int = 500) -> list[Step]:
    """The steps that make gadget ``gadget`` a UVC camera of ``formats`` (and bind it to ``udc`` when given)."""
    if not 1 <= max_packet <= 3072:
        raise GadgetError(f"streaming_maxpacket {max_packet!r} is outside 1..3072")
    ident = identity or DeviceIdentity()
    g = gadget
    steps = [Step("mkdir", g)]
    steps += [Step("write", f"{g}/{name}", f"{value:#06x}\n") for name, value in (
        ("idVendor", ident.vendor_id), ("idProduct", ident.product_id), ("bcdDevice", ident.bcd_device),
        ("bcdUSB", 0x0200), ("bDeviceClass", 0xEF), ("bDeviceSubClass", 0x02), ("bDeviceProtocol", 0x01))]
    steps.append(Step("mkdir", f"{g}/strings/{LANG}"))
    steps += [Step("write", f"{g}/strings/{LANG}/{name}", f"{text}\n") for name, text in (
        ("manufacturer", ident.manufacturer), ("product", ident.product), ("serialnumber", ident.serial))]
    fn = f"{g}/{FUNCTION}"
    steps += [Step("mkdir", fn), Step("write", f"{fn}/function_name", f"{FUNCTION_NAME}\n"),
              Step("write", f"{fn}/streaming_maxpacket", f"{max_packet}\n"),
              Step("write", f"{fn}/streaming_interval", f"{interval}\n"),
              Step("mkdir", f"{fn}/control/header/h")]
    steps += [Step("link", f"{fn}/control/class/{speed}/h", f"{fn}/control/header/h") for speed in ("fs", "ss")]
    for fmt in formats:
        d = f"{g}/{_format_dir(fmt.fourcc)}"
        steps.append(Step("mkdir", d))
        guid, bpp = FORMATS[fmt.fourcc]
        if guid is not None:
            steps += [Step("write", f"{d}/guidFormat", guid), Step("write", f"{d}/bBitsPerPixel", f"{bpp}\n")]
        for size in fmt.frames:
            f = f"{d}/{size.width}x{size.height}"
            low, high, buf = frame_rates(fmt, size)
            steps.append(Step("mkdir", f))
            steps += [Step("write", f"{f}/{name}", f"{value}\n") for name, value in (
                ("wWidth", size.width), ("wHeight", size.height), ("dwMinBitRate", low), ("dwMaxBitRate", high),
                ("dwMaxVideoFrameBufferSize", buf), ("dwDefaultFrameInterval", size.default_100ns))]
            steps.append(Step("write", f"{f}/dwFrameInterval", "".join(f"{i}\n" for i in size.intervals_100ns)))
    steps.append(Step("mkdir", f"{fn}/streaming/header/h"))
    steps += [Step("link", f"{fn}/streaming/header/h/{fmt.fourcc.lower()}", f"{g}/{_format_dir(fmt.fourcc)}")
              for fmt in formats]
    steps += [Step("link", f"{fn}/streaming/class/{speed}/h", f"{fn}/streaming/header/h")
              for speed in ("fs", "hs", "ss")]
    c = f"{g}/{CONFIG}"
    steps += [Step("mkdir", c), Step("write", f"{c}/MaxPower", f"{max_power_ma}\n"),
              Step("write", f"{c}/bmAttributes", "0x80\n"), Step("mkdir", f"{c}/strings/{LANG}"),
              Step("write", f"{c}/strings/{LANG}/configuration", "rollcam UVC\n"),
              Step("link", f"{c}/uvc.0", fn)]
    if udc is not None:
        steps.append(Step("bind", f"{g}/UDC", udc))
    return steps


class Tree:
    """The file system ``Gadget`` acts on: configfs through plain calls (tests pass a temporary folder, and a
    subclass where configfs's own behaviour is needed)."""

    def mkdir(self, path: Path) -> None:
        os.mkdir(path)

    def write(self, path: Path, data: str | bytes) -> None:
        raw = data.encode() if isinstance(data, str) else data
        with open(path, "wb", buffering=0) as f:  # one write(): configfs takes an attribute in one store
            f.write(raw)

    def symlink(self, target: Path, path: Path) -> None:
        os.symlink(target, path)

    def rmdir(self, path: Path) -> None:
        os.rmdir(path)  # configfs removes a folder's attributes with it

    def unlink(self, path: Path) -> None:
        os.unlink(path)


def find_udc(udc: str | None, udc_class: Path = UDC_CLASS) -> str:
    """The USB device controller to bind: ``udc`` checked against ``udc_class``, or the only one there."""
    names = sorted(p.name for p in udc_class.iterdir()) if udc_class.is_dir() else []
    if udc is not None:
        if udc not in names:
            raise GadgetError(f"no USB device controller {udc!r} in {udc_class} (there: {', '.join(names) or 'none'})")
        return udc
    if not names:
        raise GadgetError(f"no USB device controller in {udc_class}: this machine has no USB device port, or its "
                          "driver is not loaded (on a Raspberry Pi: dtoverlay=dwc2 in config.txt and modprobe dwc2; "
                          "for a virtual one: modprobe usbip-vudc)")
    if len(names) > 1:
        raise GadgetError(f"several USB device controllers ({', '.join(names)}): choose one with --udc")
    return names[0]


class Gadget(Closeable):
    """A configured (and, with ``udc``, bound) UVC gadget: ``open()`` applies ``steps``, ``close()`` (or an
    error while applying) undoes every step made, last first."""

    def __init__(self, steps: Sequence[Step], root: Path = CONFIGFS, tree: Tree | None = None) -> None:
        self.steps = list(steps)
        self.root = Path(root)
        self.tree = tree or Tree()
        self.done: list[Step] = []
        self.name = self.steps[0].path if self.steps else ""

    def __repr__(self) -> str:
        return f"Gadget({self.root / self.name}, {len(self.done)}/{len(self.steps)} steps applied)"

    def open(self) -> Gadget:
        """Apply the steps; on an error, undo what was made and raise ``GadgetError`` naming the step."""
        if not self.root.is_dir():
            raise GadgetError(f"{self.root} does not exist: load libcomposite (modprobe libcomposite) and mount "
                              "configfs (mount -t configfs none /sys/kernel/config)")
        if os.geteuid() != 0 and not os.access(self.root, os.W_OK):
            raise GadgetError(f"configuring a USB gadget needs root ({self.root} is not writable by this user)")
        if (self.root / self.name).exists():
            raise GadgetError(f"a gadget {self.name!r} exists already in {self.root} (another rollcam gadget, or "
                              "one left by a crash: unbind and remove it, or choose another name)")
        for step in self.steps:
            try:
                self._do(step)
            except OSError as exc:
                error = self._explain(step, exc)
                self._undo_all()
                raise error from None
            self.done.append(step)
        return self

    def _on_enter(self) -> None:
        self.open()

    def _do(self, step: Step) -> None:
        path = self.root / step.path
        if step.kind == "mkdir":
            self.tree.mkdir(path)
        elif step.kind in ("write", "bind"):
            self.tree.write(path, step.value if step.kind == "write" else f"{step.value}\n")
        elif step.kind == "link":
            self.tree.symlink(self.root / str(step.value), path)
        else:
            raise GadgetError(f"unknown configfs step {step.kind!r}")

    def _explain(self, step: Step, exc: OSError) -> GadgetError:
        where = f"{step.kind} {self.root / step.path}"
        if exc.errno in (errno.EACCES, errno.EPERM) and os.geteuid() != 0:
            return GadgetError(f"{where}: {exc.strerror}: configuring a USB gadget needs root")
        if step.path.endswith(FUNCTION) and step.kind == "mkdir":
            return GadgetError(f"{where}: {exc.strerror}: the kernel has no UVC gadget function (modprobe usb_f_uvc; "
                               "kernel option CONFIG_USB_CONFIGFS_F_UVC)")
        if step.kind == "bind":
            return GadgetError(f"{where}: {exc.strerror}: USB device controller {step.value!r} refused the gadget "
                               "(busy with another gadget, or it cannot offer an isochronous endpoint: see dmesg)")
        return GadgetError(f"{where}: {exc.strerror or exc}")

    def _undo(self, step: Step) -> None:
        path = self.root / step.path
        if step.kind == "mkdir":
            self.tree.rmdir(path)
        elif step.kind == "link":
            self.tree.unlink(path)
        elif step.kind == "bind":
            self.tree.write(path, "\n")

    def _undo_all(self) -> list[str]:
        """Undo the applied steps, last first; an undo that fails is noted and the rest still run."""
        failed = []
        while self.done:
            step = self.done.pop()
            try:
                self._undo(step)
            except OSError as exc:
                failed.append(f"{step.kind} {self.root / step.path}: {exc.strerror or exc}")
        return failed

    def _close(self) -> None:
        failed = self._undo_all()
        if failed:
            raise GadgetError("could not take the gadget down: " + "; ".join(failed))

    @property
    def bound(self) -> bool:
        """Whether the bind step has been applied."""
        return any(s.kind == "bind" for s in self.done)
