"""``GadgetServer``: the one camera as a USB webcam through Linux's UVC gadget function, configured, bound,
served and taken down as one object.

Opening it writes the configfs tree (``configfs.layout`` from the camera's formats), binds the gadget to the
USB device controller, opens the function's V4L2 node and runs ``device.GadgetStream`` on a ``Worker``. The
kernel keeps the gadget off the bus until a program opens that node, so no request is missed. Closing stops
the loop, closes the node and undoes every configfs step, last first.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from pathlib import Path

from rollcam.common.errors import DeviceError
from rollcam.common.lifecycle import Closeable, Deadline, Worker
from rollcam.emu.uvc import DeviceIdentity, FrameProducer, iso_payload_size, offered_formats
from rollcam.emu.uvc.requests import VideoControls

from .configfs import CONFIGFS, FUNCTION, MAX_PACKET, UDC_CLASS, Gadget, GadgetError, Tree, find_udc, layout
from .device import GadgetStream, udc_nodes

CLOCK_HZ = 48_000_000
"""dwClockFrequency of the function's VideoControl header as Linux's UVC function writes it (its default)."""
FOURCCS = ("YUYV", "NV12", "MJPG")
NODE_TIMEOUT_S = 10.0
VIDEO_CLASS = Path("/sys/class/video4linux")


class GadgetServer(Closeable):
    """The camera behind ``producer`` as a UVC gadget on USB device controller ``udc`` (None: the only one)."""

    def __init__(self, producer: FrameProducer, *, udc: str | None = None, identity: DeviceIdentity | None = None,
                 fourccs: Sequence[str] = FOURCCS, max_packet: int = MAX_PACKET, name: str = "rollcam",
                 frame_log: Path | None = None, root: Path = CONFIGFS, udc_class: Path = UDC_CLASS,
                 video_class: Path = VIDEO_CLASS, tree: Tree | None = None) -> None:
        self.producer = producer
        self.formats, intervals = offered_formats(producer, fourccs)
        self.controls = VideoControls(producer, self.formats, intervals, CLOCK_HZ,
                                      lambda frame_bytes, ns: iso_payload_size(frame_bytes, ns, max_packet))
        self.udc = find_udc(udc, udc_class)
        self.gadget = Gadget(layout(self.formats, identity, gadget=name, udc=self.udc, max_packet=max_packet),
                             root, tree)
        self.frame_log = frame_log
        self.video_class = video_class
        self.stream: GadgetStream | None = None
        self.worker: Worker | None = None
        self.node = ""

    def __repr__(self) -> str:
        return f"GadgetServer(udc={self.udc!r}, node={self.node!r}, {self.gadget!r})"

    def start(self) -> GadgetServer:
        """Configure and bind the gadget, open its node and start answering the host."""
        before = set(udc_nodes(self.udc, self.video_class))
        self.gadget.open()
        try:
            self.node = self._wait_node(before)
            fn = self.gadget.root / self.gadget.name / FUNCTION
            interfaces = tuple(int((fn / part / "bInterfaceNumber").read_text()) for part in ("control", "streaming"))
            self.stream = GadgetStream(self.node, self.producer, self.controls, interfaces,  # type: ignore[arg-type]
                                       self.frame_log)
            stop = threading.Event()
            self.worker = Worker(self.stream.run, stop.is_set, name="rollcam-gadget", wrap=DeviceError,
                                 stop_event=stop).start()
        except BaseException:
            self.gadget.close()
            raise
        return self

    _on_enter = start

    def _wait_node(self, before: set[str]) -> str:
        deadline = Deadline(NODE_TIMEOUT_S)
        while True:
            new = sorted(set(udc_nodes(self.udc, self.video_class)) - before)
            if new:
                return new[0]
            if deadline.expired:
                raise GadgetError(f"the UVC function bound to {self.udc!r} made no V4L2 node under it within "
                                  f"{NODE_TIMEOUT_S:.0f} s: see dmesg")
            time.sleep(0.05)

    def check(self) -> None:
        """Re-raise what stopped the gadget's loop, if it stopped."""
        if self.worker is not None:
            self.worker.check()

    def _close(self) -> None:
        try:
            if self.worker is not None:
                self.worker.close()
        finally:
            self.gadget.close()
