"""The metadata node of an emulated camera with an in-sensor network: per-frame results on a second video node.

Linux drivers deliver per-frame metadata on a second video node of buffer type ``V4L2_BUF_TYPE_META_CAPTURE``
(uvcvideo's metadata node is the model): ``V4L2_CAP_META_CAPTURE | V4L2_CAP_STREAMING``, one format
(``VIDIOC_ENUM_FMT`` / ``G_FMT`` answer a ``v4l2_meta_format`` of ``dataformat`` and ``buffersize``) and its
own buffer queue. As uvcvideo does, a metadata buffer is filled when the image node completes a buffer, and
it carries that image buffer's sequence number and timestamp; when the application has no metadata buffer
queued (or the metadata node is not streaming) that frame's metadata is lost, and the sequence numbers show
the gap. There are no controls, inputs, events or ``read()`` on this node.

``MetaDriver`` is the driver side (beside ``driver.EmuDriver``, which calls ``deliver``); ``pack`` and
``unpack`` are the ``RCIS`` layout (docs/insensor.md), little-endian:

- header (32 bytes): ``u32`` magic ``RCIS``, ``u16`` version (1), ``u16`` header size (32), ``u32`` the
  buffer's sequence, ``u16`` result count, ``u16`` flags (bit 0: results or detections were cut to fit),
  ``u64`` the buffer's timestamp (CLOCK_MONOTONIC ns, start of exposure of the image's first line), ``u32``
  bytes used, ``u32`` reserved;
- per result (48 bytes): ``i32`` sequence of the frame the network ran on (the image node's numbering),
  ``u16`` detections, ``u16`` reserved, ``u64`` that frame's start of exposure, ``u64`` its input complete,
  ``u64`` the result done (all CLOCK_MONOTONIC ns), ``u64`` its exposure (ns), ``u32`` its line time (ns),
  ``u16`` x ``u16`` the network's input size;
- per detection (24 bytes): ``f32`` x0, y0, x1, y1 in the image's pixels, ``f32`` score, ``i32`` class.
"""

from __future__ import annotations

import errno
import struct
from collections.abc import Callable
from typing import Any

import numpy as np
from rollcam.common.lifecycle import Stats

from . import raw
from .queue import BufferQueue, BufferState, V4L2Error

META_FOURCC = "RCIS"
"""rollcam in-sensor results (``v4l2_fourcc('R', 'C', 'I', 'S')``)."""
DESCRIPTION = "rollcam In-Sensor Results"
VERSION = 1
HEADER = struct.Struct("<IHHIHHQII")
RESULT = struct.Struct("<iHHQQQQIHH")
DETECTION = struct.Struct("<fffffi")
MAX_RESULTS = 4
MAX_DETECTIONS = 64
BUFFER_SIZE = 8192
"""One buffer: the header and up to ``MAX_RESULTS`` results of ``MAX_DETECTIONS`` detections each."""
assert HEADER.size + MAX_RESULTS * (RESULT.size + MAX_DETECTIONS * DETECTION.size) <= BUFFER_SIZE
TRUNCATED = 1

REQUESTS = frozenset({"QUERYCAP", "ENUM_FMT", "G_FMT", "S_FMT", "TRY_FMT", "REQBUFS", "QUERYBUF", "QBUF",
                      "DQBUF", "EXPBUF", "STREAMON", "STREAMOFF", "G_PRIORITY", "S_PRIORITY", "LOG_STATUS",
                      "ENUMINPUT", "G_INPUT", "S_INPUT"})
"""The requests a metadata node answers (uvcvideo's metadata ioctls, the core's priority and status, and the
camera's one input, which v4l2-compliance asks every capture node for)."""


def pack(sequence: int, timestamp_ns: int, results: list[Any], host_ns: Callable[[int], int], seq0: int) -> bytes:
    """One buffer's ``RCIS`` bytes of a frame's in-sensor ``results`` (device-clock times made CLOCK_MONOTONIC
    by ``host_ns``, device frame numbers made the node's sequence numbers by subtracting ``seq0``)."""
    flags = TRUNCATED if len(results) > MAX_RESULTS else 0
    body = []
    for r in results[-MAX_RESULTS:]:
        n = min(len(r), MAX_DETECTIONS)
        flags |= TRUNCATED if len(r) > n else 0
        order = np.argsort(-r.scores, kind="stable")[:n]
        w, h = (min(int(v), 0xFFFF) for v in r.input_size)
        body.append(RESULT.pack(int(r.seq) - seq0, n, 0, int(host_ns(r.timestamp_ns)), int(host_ns(r.input_ns)),
                                int(host_ns(r.done_ns)), int(r.exposure_ns), int(r.line_time_ns), w, h))
        body.extend(DETECTION.pack(*(float(v) for v in r.boxes[i]), float(r.scores[i]), int(r.classes[i]))
                    for i in order)
    payload = b"".join(body)
    used = HEADER.size + len(payload)
    head = HEADER.pack(raw.fourcc_code(META_FOURCC), VERSION, HEADER.size, sequence & 0xFFFFFFFF,
                       min(len(results), MAX_RESULTS), flags, timestamp_ns, used, 0)
    return head + payload


def unpack(data: bytes) -> dict[str, Any]:
    """The ``RCIS`` buffer ``data`` as a dictionary (the reader's side; ValueError when it is not one)."""
    if len(data) < HEADER.size:
        raise ValueError(f"{len(data)} bytes is shorter than the {HEADER.size}-byte RCIS header")
    magic, version, size, seq, count, flags, ts, used, _ = HEADER.unpack_from(data)
    if magic != raw.fourcc_code(META_FOURCC) or version != VERSION or used > len(data):
        raise ValueError(f"not an RCIS v{VERSION} buffer (magic {magic:#x}, version {version}, {used} bytes)")
    pos, results = size, []
    for _ in range(count):
        src, n, _r, t0, t_in, t_done, exposure, line, w, h = RESULT.unpack_from(data, pos)
        pos += RESULT.size
        dets = []
        for _ in range(n):
            *box, score, cls = DETECTION.unpack_from(data, pos)
            pos += DETECTION.size
            dets.append({"box": box, "score": score, "cls": cls})
        results.append({"sequence": src, "timestamp_ns": t0, "input_ns": t_in, "done_ns": t_done,
                        "exposure_ns": exposure, "line_time_ns": line, "input_size": (w, h), "detections": dets})
    return {"sequence": seq, "timestamp_ns": ts, "truncated": bool(flags & TRUNCATED), "results": results}


class MetaDriver:
    """Driver state of one metadata node: the image driver it belongs to, its own buffer queue."""

    buf_type = raw.BufType.META_CAPTURE
    requests = REQUESTS

    def __init__(self, video: Any, alloc: Callable[[int, int], np.ndarray] | None = None) -> None:
        self.video = video
        self.camera = video.camera
        self.queue = BufferQueue(alloc=alloc)
        self.on_change: Callable[[], None] | None = None
        self.stats = Stats()
        self.delivered = self.dropped_no_buffer = 0
        video.meta = self

    def ioctl(self, request: raw.Ioctl | str, arg: Any = None) -> Any:
        """Run one VIDIOC request of ``REQUESTS``; failures raise V4L2Error with the kernel's errno."""
        request = raw.Ioctl(request)
        if self.queue.disconnected or self.video.queue.disconnected:
            raise V4L2Error(errno.ENODEV, f"{request.value}: device disconnected")
        handler = _HANDLERS.get(request)
        if handler is None:
            raise V4L2Error(errno.ENOTTY, f"{request.value} is not a metadata node request")
        return handler(self, arg)

    def admit(self, request: raw.Ioctl) -> None:
        """ENODEV once the camera is unplugged (as the image node's)."""
        if self.video.queue.disconnected:
            raise V4L2Error(errno.ENODEV, f"{request.value}: device disconnected")

    def deliver(self, frame: Any, sequence: int, timestamp_ns: int) -> None:
        """The image node completed a buffer of ``frame`` with ``sequence`` and ``timestamp_ns``: fill the next
        queued metadata buffer with its results (none queued: this frame's metadata is lost)."""
        slot = self.queue.take()
        if slot is None:
            self.dropped_no_buffer += 1
            return
        data = pack(sequence, timestamp_ns, list(frame.insensor or ()), self.camera.host_ns, self.video.seq0)
        slot.memory[: len(data)] = np.frombuffer(data, np.uint8)
        self.queue.complete(slot, bytesused=len(data), sequence=sequence, timestamp_ns=timestamp_ns, error=False)
        self.delivered += 1
        if self.on_change is not None:
            self.on_change()

    def close(self) -> None:
        """Stop streaming and free the buffers (idempotent)."""
        self.queue.stop()
        self.queue.disconnected = False


def _querycap(d: MetaDriver, _arg: Any) -> raw.Capability:
    caps = raw.Cap.META_CAPTURE | raw.Cap.STREAMING
    every = caps | raw.Cap.VIDEO_CAPTURE | raw.Cap.READWRITE | raw.Cap.EXT_PIX_FORMAT  # the image node's too
    return raw.Capability("rollcam", f"rollcam {d.camera.sensor.name} emulator", "platform:rollcam-emu",
                          0x00060800, int(every | raw.Cap.DEVICE_CAPS), int(caps))


def _enum_fmt(_d: MetaDriver, arg: raw.FmtDesc) -> raw.FmtDesc:
    if arg.index != 0:
        raise V4L2Error(errno.EINVAL, f"format index {arg.index} out of range")
    return raw.FmtDesc(0, raw.BufType.META_CAPTURE, 0, DESCRIPTION, META_FOURCC)


def _reqbufs(d: MetaDriver, arg: raw.RequestBuffers) -> raw.RequestBuffers:
    return raw.RequestBuffers(d.queue.request(arg.count, arg.memory, BUFFER_SIZE), arg.type, arg.memory)


def _qbuf(d: MetaDriver, arg: raw.Buffer) -> BufferState:
    d.queue.queue(arg.index)
    return d.queue.query(arg.index)


def _dqbuf(d: MetaDriver, arg: dict[str, Any] | None) -> Any:
    opts = arg or {}
    return d.queue.dequeue(opts.get("block", True), opts.get("timeout_s"))


_HANDLERS: dict[raw.Ioctl, Callable[[MetaDriver, Any], Any]] = {
    raw.Ioctl.QUERYCAP: _querycap, raw.Ioctl.ENUM_FMT: _enum_fmt, raw.Ioctl.REQBUFS: _reqbufs,
    raw.Ioctl.QUERYBUF: lambda d, a: d.queue.query(a.index), raw.Ioctl.QBUF: _qbuf, raw.Ioctl.DQBUF: _dqbuf,
    raw.Ioctl.STREAMON: lambda d, _a: d.queue.start(), raw.Ioctl.STREAMOFF: lambda d, _a: d.queue.stop(),
    raw.Ioctl.ENUMINPUT: lambda d, a: d.video.ioctl(raw.Ioctl.ENUMINPUT, a),
    raw.Ioctl.G_INPUT: lambda d, a: d.video.ioctl(raw.Ioctl.G_INPUT, a),
    raw.Ioctl.S_INPUT: lambda d, a: d.video.ioctl(raw.Ioctl.S_INPUT, a),
}
