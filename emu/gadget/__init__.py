"""The emulated camera as a real USB webcam: Linux's UVC gadget function (``usb_f_uvc``) on a board's USB
device controller, configured through configfs from the one camera spec and fed by the one ``FirmwareCamera``.

Layers: ``uapi`` (the kernel's g_uvc.h beside V4L2's structures), ``configfs`` (the function's tree as data,
applied and undone), ``requests`` (SETUP/DATA answers, pure), ``device`` (the V4L2 output node's event and
buffer loop), ``server`` (all of it as one object). ``rollcam gadget`` is the command line (docs/gadget.md).
"""

from __future__ import annotations

from .configfs import Gadget, GadgetError, Step, Tree, find_udc, layout
from .requests import SetupHandler
from .server import GadgetServer

__all__ = ["Gadget", "GadgetError", "GadgetServer", "SetupHandler", "Step", "Tree", "find_udc", "layout"]
