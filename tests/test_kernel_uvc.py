"""rollcam's UVC camera as Linux's own drivers see it: USB/IP -> vhci-hcd -> uvcvideo -> /dev/videoN in a guest.

The guest (``guest.py``) boots Debian's stock kernel under QEMU; the camera is served by a rollcam USB/IP server
on the host and attached with Linux's ``usbip``; ``v4l2-ctl`` streams it. Every frame the guest captures must be
byte-for-byte a frame the emulator sent (its encoded YUYV, NV12 or MJPEG), in order.
"""

from __future__ import annotations

import contextlib
import hashlib
import re
import threading
from collections.abc import Iterator
from dataclasses import dataclass

import pytest
from rollcam.emu.usbip.server import USBIPServer
from rollcam.emu.uvc import DeviceIdentity, FirmwareProducer, UVCFunction
from rollcam.emu.uvc.convert import encode
from rollcam.firmware.camera import FirmwareCamera

pytestmark = pytest.mark.kernel

TROUBLE = re.compile(r"cannot find a urb of seqnum|Non-zero status|uvcvideo.*(fail|error)|usb 1-1: USB disconnect")
"""What uvcvideo and vhci-hcd print when a device misbehaves: a reply to a URB vhci no longer has (it then drops
the device), a URB that ended in an error, a device gone while attached."""


class RecordingProducer:
    """A ``FrameProducer`` that keeps the digest of every frame as the stream encodes it (the committed format),
    so frames captured elsewhere can be matched to the emulator's by content."""

    def __init__(self, inner: FirmwareProducer) -> None:
        self.inner = inner
        self.function: UVCFunction | None = None
        self.digests: dict[bytes, int] = {}
        self._lock = threading.Lock()

    def __getattr__(self, name: str):
        return getattr(self.inner, name)

    def frame(self, index: int):
        frame = self.inner.frame(index)
        committed = self.function.controls.committed
        data = encode(frame.data, committed.fourcc, committed.jpeg_quality)
        with self._lock:
            self.digests[hashlib.sha1(data.tobytes()).digest()] = index
        return frame


@dataclass
class Attached:
    """A rollcam camera attached in the guest: its capture node and the host side that serves it."""

    node: str
    function: UVCFunction
    recorder: RecordingProducer
    server: USBIPServer
    port: int
    dmesg_from: int  # lines of the guest's kernel log before the attach


@contextlib.contextmanager
def attached_camera(guest, transfer: str, *, scene: str = "street") -> Iterator[Attached]:
    """Serve an emulated imx219 over USB/IP on the host, attach it in the guest, and detach it at the end."""
    camera = FirmwareCamera("imx219", scene={"scene": scene, "seed": 3})
    recorder = RecordingProducer(FirmwareProducer(camera))
    function = UVCFunction(recorder, transfer=transfer, realtime=True,
                           identity=DeviceIdentity(serial=camera.serial_number))
    recorder.function = function
    with function, USBIPServer([function], "127.0.0.1", 0) as server, guest.usbip_port(server.address) as port:
        start = len(guest.dmesg().splitlines())
        guest.sh(f"usbip --tcp-port {port} attach -r 127.0.0.1 -b 1-1")
        try:
            yield Attached(guest.video_node("rollcam"), function, recorder, server, port, start)
        finally:
            guest.sh("for p in $(usbip port 2>/dev/null | sed -n 's/^Port \\([0-9]*\\): <Port in Use>.*/\\1/p'); "
                     "do usbip detach -p $p; done; "
                     "for i in $(seq 100); do grep -qs rollcam /sys/class/video4linux/*/name || exit 0; sleep 0.1; "
                     "done; exit 1")


def capture(guest, node: str, fourcc: str, width: int, height: int, count: int,
            timeout_s: float = 120) -> list[tuple[int, bytes]]:
    """Stream ``count`` frames with ``v4l2-ctl`` in the guest; returns (sequence, bytes) of each buffer."""
    out = f"cap-{fourcc}-{width}x{height}.raw"
    _, log = guest.sh(f"v4l2-ctl -d {node} --set-fmt-video=width={width},height={height},pixelformat={fourcc} "
                      f"--stream-mmap=4 --stream-count={count} --stream-to=/mnt/{out} --verbose",
                      timeout_s=timeout_s)
    raw = (guest.xchg / out).read_bytes()
    (guest.xchg / out).unlink()
    frames, pos = [], 0
    for m in re.finditer(r"cap dqbuf: \d+ seq:\s*(\d+) bytesused: (\d+)", log):
        n = int(m.group(2))
        frames.append((int(m.group(1)), raw[pos:pos + n]))
        pos += n
    assert len(frames) == count and pos == len(raw), log[-2000:]
    return frames


def assert_emulators_frames(att: Attached, frames: list[tuple[int, bytes]]) -> None:
    """Every captured frame is, byte for byte, a frame the emulator encoded, in the emulator's order."""
    indices = []
    for seq, data in frames:
        index = att.recorder.digests.get(hashlib.sha1(data).digest())
        assert index is not None, f"guest frame seq {seq} ({len(data)} bytes) is no frame the emulator sent"
        indices.append(index)
    assert indices == sorted(set(indices)), indices


def assert_device_kept(guest, att: Attached) -> None:
    """The kernel said nothing of trouble since the attach, and the camera is still there."""
    log = guest.dmesg().splitlines()[att.dmesg_from:]
    bad = [line for line in log if TROUBLE.search(line)]
    assert not bad, "\n".join(bad[-10:])
    assert guest.video_node("rollcam", timeout_s=1) == att.node


FORMATS = ("YUYV", "NV12", "MJPG")


@pytest.mark.parametrize("transfer", ["iso", "bulk"])
def test_uvcvideo_streams_every_format_as_the_emulator_sends_it(kernel_guest, transfer):
    with attached_camera(kernel_guest, transfer) as att:
        for fourcc in FORMATS:
            for width, height, count in ((640, 480, 8), (1920, 1080, 3)):
                frames = capture(kernel_guest, att.node, fourcc, width, height, count)
                assert_emulators_frames(att, frames)
        assert att.function.stats.frames_sent > 0
        assert_device_kept(kernel_guest, att)


@pytest.mark.parametrize("transfer", ["iso", "bulk"])
def test_stream_off_keeps_the_device_through_50_cycles(kernel_guest, transfer):
    """Each v4l2-ctl run is a stream-on and a stream-off; uvcvideo unlinks the URBs in flight at each stop."""
    with attached_camera(kernel_guest, transfer) as att:
        kernel_guest.sh(f"v4l2-ctl -d {att.node} --set-fmt-video=width=640,height=480,pixelformat=YUYV\n"
                        f"for i in $(seq 50); do v4l2-ctl -d {att.node} --stream-mmap=4 --stream-count=2 "
                        "--stream-to=/dev/null || exit 1; done", timeout_s=600)
        frames = capture(kernel_guest, att.node, "YUYV", 640, 480, 3)
        assert_emulators_frames(att, frames)
        assert att.server.stats.unlinked > 0  # the stops did unlink running URBs
        assert_device_kept(kernel_guest, att)


def test_detach_while_streaming_frees_the_device_for_the_next_attach(kernel_guest):
    with attached_camera(kernel_guest, "iso") as att:
        kernel_guest.sh(f"setsid v4l2-ctl -d {att.node} --stream-mmap=4 --stream-count=100000 "
                        "--stream-to=/dev/null </dev/null >/tmp/long.log 2>&1 &\n"
                        "sleep 3; usbip detach -p 0")
        with kernel_guest.usbip_port(att.server.address) as port:
            kernel_guest.sh(f"usbip --tcp-port {port} attach -r 127.0.0.1 -b 1-1")
            node = kernel_guest.video_node("rollcam")
            assert_emulators_frames(att, capture(kernel_guest, node, "YUYV", 640, 480, 4))
