"""The gadget side of the UVC camera: the UVC function's V4L2 output node, driven from the one camera.

``GadgetStream`` runs the loop every UVC gadget program runs (Documentation/usb/gadget_uvc.rst): subscribe to
the UVC events, answer SETUP/DATA with ``UVCIOC_SEND_RESPONSE`` (``requests.SetupHandler``), and on STREAMON set
the committed format, request and queue output buffers and start the queue; fill each buffer the kernel gives
back with the next frame due; on STREAMOFF or DISCONNECT stop the queue, free the buffers and wait again.

Frames come from the ``FrameProducer`` over the one ``FirmwareCamera`` (the frames of ``rollcam emulate``),
made on time by ``rollcam.emu.uvc.ahead.RenderAhead`` and encoded by ``rollcam.emu.uvc.convert.encode``, exactly
as the emulated USB camera's are. What goes on the wire differs in the payload headers only: Linux 6.1's UVC
function writes them itself, two bytes (bHeaderLength 2, FID/EOF/EOH): no PTS, no SCR and no in-sensor
metadata item can be sent on this path (later kernels add a PTS and an SCR of their own 48 MHz clock, from the
buffer's timestamp, which this program sets to the frame's device time). 6.1's node accepts YUYV and MJPEG
formats only: a frame of another uncompressed format (NV12) travels in a YUYV-sized buffer with ``bytesused``
its own size; the kernel sends ``bytesused`` bytes.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import logging
import mmap
import os
import select
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from rollcam.common.errors import DeviceError
from rollcam.emu.uvc import constants as C
from rollcam.emu.uvc.ahead import RenderAhead
from rollcam.emu.uvc.convert import encode, wire_layout
from rollcam.emu.uvc.producer import FrameProducer
from rollcam.emu.uvc.requests import Committed, VideoControls
from rollcam.emu.uvc.stream import StreamStats
from rollcam.emu.v4l2.abi import REQUESTS
from rollcam.emu.v4l2.raw import Buffer, Event, Format, RequestBuffers, fourcc_code

from . import uapi
from .requests import SetupHandler

log = logging.getLogger("rollcam.gadget")
N_BUFFERS = 4
MEMORY_MMAP = 1
POLL_MS = 100  # longest wait in the loop, so a stop is prompt


def ioctl(fd: int, name: str, arg: Any) -> Any:
    """``ioctl(fd, VIDIOC_<name>, arg)`` (or ``UVCIOC_SEND_RESPONSE``), raising OSError as the kernel answers."""
    number = uapi.UVCIOC_SEND_RESPONSE if name == "SEND_RESPONSE" else REQUESTS[name][0]
    fcntl.ioctl(fd, number, arg)
    return arg


def udc_nodes(udc: str, sysfs: Path = Path("/sys/class/video4linux")) -> list[str]:
    """The /dev paths of the V4L2 nodes whose device sits under USB device controller ``udc`` (a UVC gadget
    function's node hangs off its gadget, a child of the controller). Read from sysfs without opening a node:
    opening a UVC function's node connects its gadget to the bus, and closing it disconnects it."""
    out = []
    for entry in sorted(sysfs.glob("video*")):
        try:
            parents = (entry / "device").resolve(strict=True).parts
        except OSError:
            continue
        if udc in parents:
            out.append(f"/dev/{entry.name}")
    return out


@dataclass
class GadgetStats(StreamStats):
    """What the gadget did: the stream's counters (STALLs among them), plus events and stream starts."""

    events: int = 0
    streams: int = 0


class FrameLog:
    """One JSON line per frame the gadget queued: device sequence, format, size, bytes and SHA-1 of the
    bytes, so what a host captured can be matched to the emulator's frames."""

    def __init__(self, path: Path | None) -> None:
        self.file: IO[str] | None = open(path, "a", buffering=1) if path else None  # noqa: SIM115 (close())

    def write(self, sequence: int, committed: Committed, data: bytes) -> None:
        if self.file is not None:
            self.file.write(json.dumps({"sequence": sequence, "fourcc": committed.fourcc, "width": committed.width,
                                        "height": committed.height, "bytes": len(data),
                                        "sha1": hashlib.sha1(data).hexdigest()}) + "\n")

    def close(self) -> None:
        if self.file is not None:
            self.file.close()
            self.file = None


IoctlCall = Callable[[int, str, Any], Any]
"""How the gadget talks to its node: ``ioctl`` above, or a test's stand-in for the kernel's UVC function."""


class OutputQueue:
    """The node's MMAP output buffers while a stream runs: format set, buffers mapped, started, stopped."""

    def __init__(self, fd: int, committed: Committed, ioctl: IoctlCall = ioctl) -> None:
        self.fd, self.committed, self.ioctl = fd, committed, ioctl
        layout = wire_layout(committed.fourcc)
        fmt = Format(type=uapi.BUF_TYPE_VIDEO_OUTPUT)
        pix = fmt.fmt.pix
        pix.width, pix.height = committed.width, committed.height
        pix.sizeimage = committed.probe.dwMaxVideoFrameSize
        pix.pixelformat = fourcc_code(committed.fourcc)
        try:
            self.ioctl(fd, "S_FMT", fmt)
        except OSError as exc:
            if exc.errno != errno.EINVAL or layout is None:
                raise
            # 6.1's node knows YUYV and MJPEG only: a YUYV buffer of the size holds any 8-16 bit frame.
            pix.pixelformat = uapi.V4L2_PIX_FMT_YUYV
            self.ioctl(fd, "S_FMT", fmt)
        req = self.ioctl(fd, "REQBUFS", RequestBuffers(count=N_BUFFERS, type=uapi.BUF_TYPE_VIDEO_OUTPUT,
                                                  memory=MEMORY_MMAP))
        self.maps: list[mmap.mmap] = []
        try:
            for i in range(req.count):
                b = self.ioctl(fd, "QUERYBUF", Buffer(index=i, type=uapi.BUF_TYPE_VIDEO_OUTPUT, memory=MEMORY_MMAP))
                self.maps.append(mmap.mmap(fd, b.length, mmap.MAP_SHARED, mmap.PROT_READ | mmap.PROT_WRITE,
                                           offset=b.m.offset))
        except BaseException:
            self.close()
            raise
        self.free = list(range(len(self.maps)))
        # Started at once, with no buffer queued: the host's SET_INTERFACE waits for it (the kernel completes
        # its status stage at STREAMON), and the first frame may take longer than that to render.
        self.ioctl(fd, "STREAMON", _output_type())

    def queue(self, data: bytes, timestamp_ns: int) -> None:
        """Put ``data`` in a free buffer and queue it (starting the stream with the first)."""
        index = self.free.pop(0)
        m = self.maps[index]
        if len(data) > len(m):
            raise DeviceError(f"a {len(data)}-byte frame does not fit the gadget's {len(m)}-byte buffer")
        m[:len(data)] = data
        b = Buffer(index=index, type=uapi.BUF_TYPE_VIDEO_OUTPUT, memory=MEMORY_MMAP, bytesused=len(data))
        b.timestamp_ns = timestamp_ns
        self.ioctl(self.fd, "QBUF", b)

    def reclaim(self) -> None:
        """Take back every buffer the kernel has sent."""
        while True:
            b = Buffer(type=uapi.BUF_TYPE_VIDEO_OUTPUT, memory=MEMORY_MMAP)
            try:
                self.ioctl(self.fd, "DQBUF", b)
            except OSError as exc:
                if exc.errno in (errno.EAGAIN, errno.EINVAL, errno.EPIPE, errno.ENODEV):
                    return
                raise
            self.free.append(b.index)

    def close(self) -> None:
        """Stop the queue and free the buffers (what a STREAMOFF event asks for)."""
        for m in self.maps:
            m.close()
        self.maps = []
        for name, arg in (("STREAMOFF", _output_type()),
                          ("REQBUFS", RequestBuffers(count=0, type=uapi.BUF_TYPE_VIDEO_OUTPUT, memory=MEMORY_MMAP))):
            _ioctl_logged(self.ioctl, self.fd, name, arg)


def _ioctl_logged(io: IoctlCall, fd: int, name: str, arg: Any) -> None:
    """An ioctl whose failure is only logged (stopping a stream the host already left must still work)."""
    try:
        io(fd, name, arg)
    except OSError as exc:
        log.info("UVC gadget: %s: %s", name, exc.strerror)


def _output_type() -> Any:
    """The ``int`` argument of STREAMON/STREAMOFF for the output queue."""
    return REQUESTS["STREAMON"][1](uapi.BUF_TYPE_VIDEO_OUTPUT)


class GadgetStream:
    """The event loop of one UVC function node: ``run(stopping)`` until ``stopping()`` is true."""

    def __init__(self, node: str, producer: FrameProducer, controls: VideoControls,
                 interfaces: tuple[int, int] = (0, 1), frame_log: Path | None = None,
                 ioctl: IoctlCall = ioctl) -> None:
        self.node, self.producer, self.controls, self.ioctl = node, producer, controls, ioctl
        self.handler = SetupHandler(controls, interfaces)
        self.stats = GadgetStats()
        self.frame_log = FrameLog(frame_log)
        self.queue: OutputQueue | None = None
        self.ahead: RenderAhead | None = None
        self.connected = False
        self.fd = os.open(node, os.O_RDWR | os.O_NONBLOCK)
        try:
            for event_type in uapi.UVC_EVENTS:
                self.ioctl(self.fd, "SUBSCRIBE_EVENT", uapi.subscription(event_type))
        except BaseException:
            os.close(self.fd)
            raise

    def __repr__(self) -> str:
        return f"GadgetStream({self.node!r}, connected={self.connected}, streaming={self.queue is not None})"

    def run(self, stopping: Callable[[], bool]) -> None:
        """Answer events and feed the stream until ``stopping()``; the node is closed on the way out."""
        poller = select.poll()
        try:
            while not stopping():
                # POLLOUT only while the queue streams: vb2 answers EPOLLERR to it at once on a stopped queue.
                poller.register(self.fd, select.POLLPRI | (select.POLLOUT if self.queue is not None else 0))
                wait_ms = self._feed() if self.queue is not None else POLL_MS
                for _fd, mask in poller.poll(wait_ms):
                    if mask & select.POLLPRI:
                        self._events()
                    if mask & (select.POLLOUT | select.POLLERR) and self.queue is not None:
                        self.queue.reclaim()
        finally:
            self._stop_stream()
            self.frame_log.close()
            os.close(self.fd)

    # ------------------------------------------------------------------------------------------ events
    def _events(self) -> None:
        while True:
            event = Event()
            try:
                self.ioctl(self.fd, "DQEVENT", event)
            except OSError as exc:
                if exc.errno == errno.ENOENT:  # no more events
                    return
                raise
            self.stats.events += 1
            self._event(event)

    def _event(self, event: Event) -> None:
        t = event.type
        if t == uapi.UVC_EVENT_SETUP:
            self._respond(self.handler.setup(uapi.event_request(event)))
        elif t == uapi.UVC_EVENT_DATA:
            self.handler.data(uapi.event_data(event))
        elif t == uapi.UVC_EVENT_CONNECT:
            self.connected = True
            log.info("UVC gadget: connected")
        elif t == uapi.UVC_EVENT_DISCONNECT:
            self.connected = False
            self._stop_stream()
            log.info("UVC gadget: disconnected")
        elif t == uapi.UVC_EVENT_STREAMON:
            self._start_stream()
        elif t == uapi.UVC_EVENT_STREAMOFF:
            self._stop_stream()
        self.stats.stalls = self.handler.stalls

    def _respond(self, data: bytes | None) -> None:
        try:
            self.ioctl(self.fd, "SEND_RESPONSE", uapi.response(data))
        except OSError as exc:  # the host gave up on the request (a timeout, a reset): nothing to answer
            log.info("UVC gadget: response not sent: %s", exc.strerror)

    # ------------------------------------------------------------------------------------------ stream
    def _start_stream(self) -> None:
        self._stop_stream()
        committed = self.controls.committed
        if committed is None:  # a host that streams without a commit gets the current probe
            self.controls.request(C.SET_CUR, 1, 0, C.VS_COMMIT_CONTROL, C.PROBE_LEN_15, self.controls.probe.pack())
            committed = self.controls.committed
        assert committed is not None
        try:
            self.queue = OutputQueue(self.fd, committed, self.ioctl)
        except OSError as exc:  # the host left, or the node refused the format: wait for the next stream
            log.warning("UVC gadget: cannot start %s %dx%d on %s: %s", committed.fourcc, committed.width,
                        committed.height, self.node, exc.strerror or exc)
            return
        self.controls.streaming = True
        self.ahead = RenderAhead(self.producer, lambda f: encode(f.data, committed.fourcc, committed.jpeg_quality),
                                 self.stats)
        self.stats.streams += 1
        log.info("UVC gadget: streaming %s %dx%d", committed.fourcc, committed.width, committed.height)

    def _feed(self) -> int:
        """Queue the frames that are due into free buffers; returns how long (ms) to wait for the next."""
        queue, ahead = self.queue, self.ahead
        assert queue is not None and ahead is not None
        while queue.free:
            got = ahead.take()
            if isinstance(got, int):
                return max(1, min(POLL_MS, got // 1_000_000))
            _index, frame, data = got
            raw = data.tobytes()
            try:
                queue.queue(raw, frame.timestamp_ns)
            except OSError as exc:
                if exc.errno != errno.ENODEV:
                    raise
                # The host left the stream (SET_INTERFACE 0, a reset): the function gave its requests back with
                # -ESHUTDOWN and refuses buffers until the queue is stopped. Its STREAMOFF event may still be on
                # the way; stopping now (STREAMOFF clears the refusal) readies the next stream.
                log.info("UVC gadget: the host left the stream; frame %d not sent", frame.sequence)
                self._stop_stream()
                return POLL_MS
            self.frame_log.write(frame.sequence, queue.committed, raw)
            self.stats.frames_sent += 1
        return POLL_MS

    def _stop_stream(self) -> None:
        self.controls.streaming = False
        if self.ahead is not None:
            self.ahead.stop()
            self.ahead = None
        if self.queue is not None:
            self.queue.close()
            self.queue = None
