"""rollcam's UVC camera as Linux's own drivers see it: USB/IP -> vhci-hcd -> uvcvideo -> /dev/videoN in a guest.

The guest (``guest.py``) boots Debian's stock kernel under QEMU; the camera is served by a rollcam USB/IP server
on the host and attached with Linux's ``usbip``; ``v4l2-ctl`` streams it. Every frame the guest captures must be
byte-for-byte a frame the emulator sent (its encoded YUYV, NV12 or MJPEG), in order.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import re
import sys
import threading
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import guest as guest_module
import numpy as np
import pytest
from helpers import wait_for
from rollcam.emu.usbip.server import ServerLimits, USBIPServer
from rollcam.emu.uvc import DeviceIdentity, FirmwareProducer, UVCFunction
from rollcam.emu.uvc.convert import encode
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.imaging import warm
from rollcam.firmware.spec import CameraSpec
from rollcam.host.sources import open_camera

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
        self.bgr_digests: dict[bytes, int] = {}  # of YUYV frames as OpenCV's V4L2 backend converts them
        self.frames: dict[int, EmulatorFrame] = {}
        self._lock = threading.Lock()

    def __getattr__(self, name: str):
        return getattr(self.inner, name)

    def frame(self, index: int):
        frame = self.inner.frame(index)
        committed = self.function.controls.committed
        data = encode(frame.data, committed.fourcc, committed.jpeg_quality)
        bgr = None
        if committed.fourcc == "YUYV":
            h, w = frame.data.shape[:2]
            bgr = hashlib.sha1(cv2.cvtColor(data.reshape(h, w, 2), cv2.COLOR_YUV2BGR_YUYV).tobytes()).digest()
        with self._lock:
            self.digests[hashlib.sha1(data.tobytes()).digest()] = index
            if bgr is not None:
                self.bgr_digests[bgr] = index
            self.frames[index] = EmulatorFrame(frame.sequence, frame.timestamp_ns, frame.insensor,
                                               frame.row_times_ns)
        return frame


@dataclass(frozen=True)
class EmulatorFrame:
    """What the emulator knows of a frame it sent: device sequence, first row's start of exposure, in-sensor
    results, and every row's sample time (mid-exposure, device clock ns)."""

    sequence: int
    timestamp_ns: int
    insensor: tuple | None
    row_times_ns: np.ndarray


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
def attached_camera(guest, transfer: str, *, usb_id: tuple[int, int] | None = None,
                    **options: str) -> Iterator[Attached]:
    """Serve an emulated imx219 (spec ``options``, a street scene by default) over USB/IP on the host, attach it
    in the guest, and detach it at the end."""
    camera = FirmwareCamera(CameraSpec.from_options("imx219", {"scene": "street", "seed": "3", **options}))
    # Compiled before the attach: on a cold cache the first commit would compile the renderer for longer than
    # uvcvideo waits for its answer or v4l2-ctl for a frame (a fresh clone's first kernel test).
    warm(camera.spec)
    recorder = RecordingProducer(FirmwareProducer(camera))
    ids = {} if usb_id is None else {"vendor_id": usb_id[0], "product_id": usb_id[1]}
    function = UVCFunction(recorder, transfer=transfer, realtime=True,
                           identity=DeviceIdentity(serial=camera.serial_number, **ids))
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


def v4l2_ctl_buffers(log: str, raw: bytes) -> list[tuple[int, bytes]]:
    """(sequence, bytes) of each buffer ``v4l2-ctl --verbose --stream-to`` logged and wrote."""
    frames, pos = [], 0
    for m in re.finditer(r"cap dqbuf: \d+ seq:\s*(\d+) bytesused:\s*(\d+)", log):
        n = int(m.group(2))
        frames.append((int(m.group(1)), raw[pos:pos + n]))
        pos += n
    assert pos == len(raw), log[-2000:]
    return frames


def capture(guest, node: str, fourcc: str, width: int, height: int, count: int,
            timeout_s: float = 120) -> list[tuple[int, bytes]]:
    """Stream ``count`` frames with ``v4l2-ctl`` in the guest; returns (sequence, bytes) of each buffer."""
    out = f"cap-{fourcc}-{width}x{height}.raw"
    _, log = guest.sh(f"v4l2-ctl -d {node} --set-fmt-video=width={width},height={height},pixelformat={fourcc} "
                      f"--stream-mmap=4 --stream-count={count} --stream-to=/mnt/{out} --verbose",
                      timeout_s=timeout_s)
    frames = v4l2_ctl_buffers(log, (guest.xchg / out).read_bytes())
    (guest.xchg / out).unlink()
    assert len(frames) == count
    return frames


def capture_with_metadata(guest, node: str, meta: str, count: int,
                          ) -> tuple[list[tuple[int, bytes]], dict[int, bytes]]:
    """YUYV 640x480 frames and, captured from the same stream on the metadata node, the metadata buffers of
    ``count`` of them by sequence number."""
    _, log = guest.sh(f"timeout 60 v4l2-ctl -d {meta} --stream-mmap=4 --stream-count={count} "
                      "--stream-to=/mnt/meta.raw --verbose >/tmp/meta.log 2>&1 &\n"
                      "sleep 1\n"
                      f"v4l2-ctl -d {node} --set-fmt-video=width=640,height=480,pixelformat=YUYV --stream-mmap=4 "
                      f"--stream-count={count + 4} --stream-to=/mnt/video.raw --verbose >/tmp/video.log 2>&1\n"
                      "wait; cat /tmp/video.log; echo ==META==; cat /tmp/meta.log", timeout_s=180)
    video_log, meta_log = log.split("==META==")
    frames = v4l2_ctl_buffers(video_log, (guest.xchg / "video.raw").read_bytes())
    metas = dict(v4l2_ctl_buffers(meta_log, (guest.xchg / "meta.raw").read_bytes()))
    assert len(metas) == count, meta_log[-2000:]
    return frames, metas


def payload_headers(meta: bytes) -> list[bytes]:
    """The payload headers in one ``UVCH`` metadata buffer: ``struct uvc_meta_buf`` (u64 ns, u16 sof), then the
    header's standard part (bLength keeps the whole header's length; only 2 bytes, PTS and SCR are copied)."""
    out, pos = [], 0
    while pos + 12 <= len(meta):
        flags = meta[pos + 11]
        n = 2 + 4 * bool(flags & 0x04) + 6 * bool(flags & 0x08)
        out.append(meta[pos + 10:pos + 10 + n])
        pos += 10 + n
    return out


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


def test_detach_while_streaming_frees_the_device_for_the_next_attach(kernel_guests):
    """Debian 6.1's uvcvideo can itself break when its device goes while it streams: CI met a refcount underflow
    and a list corruption in ``uvc_video_copy_data_work`` / ``uvc_buffer_queue`` once, a race inside the guest's
    driver between its URB copy work and the disconnect. A crash inside uvcvideo therefore runs the test once more
    in a fresh guest (with a warning quoting it); it fails if the kernel breaks again, breaks elsewhere, or the
    camera does not come back."""
    for attempt in (1, 2):
        g = kernel_guests.get()
        error: Exception | None = None
        try:
            _detach_while_streaming_and_attach_again(g)
        except Exception as exc:
            error = exc
        crash = g.oops()
        if crash is not None and attempt == 1 and "uvc" in crash:
            warnings.warn(f"the guest's uvcvideo broke at the detach; once more in a fresh guest:\n{crash}",
                          stacklevel=1)
            continue
        if error is not None:
            raise error
        if crash is not None:
            pytest.fail(f"the guest kernel broke at the detach:\n{crash}", pytrace=False)
        return


def _detach_while_streaming_and_attach_again(g) -> None:
    with attached_camera(g, "iso") as att:
        g.sh(f"setsid v4l2-ctl -d {att.node} --stream-mmap=4 --stream-count=100000 "
             "--stream-to=/dev/null </dev/null >/tmp/long.log 2>&1 &\n"
             "sleep 3; usbip detach -p 0")
        with g.usbip_port(att.server.address) as port:
            g.sh(f"usbip --tcp-port {port} attach -r 127.0.0.1 -b 1-1")
            node = g.video_node("rollcam")
            assert_emulators_frames(att, capture(g, node, "YUYV", 640, 480, 4))


def test_the_metadata_node_carries_each_frames_pts_and_scr(kernel_guest):
    with attached_camera(kernel_guest, "iso") as att:
        meta = kernel_guest.video_node("rollcam", 1)
        frames, metas = capture_with_metadata(kernel_guest, att.node, meta, 6)
        assert_emulators_frames(att, frames)
        for seq, data in frames:
            if seq not in metas:
                continue
            index = att.recorder.digests[hashlib.sha1(data).digest()]
            header = payload_headers(metas[seq])[0]
            assert header[1] & 0x0C == 0x0C  # PTS and SCR present
            pts = int.from_bytes(header[2:6], "little")
            assert pts == att.recorder.frames[index].timestamp_ns % 2**32  # the 1 GHz device clock of its first row



KNOWN_COMPLIANCE_FAILURES = {
    # v4l-utils 1.22.1 names NV12 'Y/CbCr 4:2:0', kernel 6.1 'Y/UV 4:2:0': the kernel's vivid fails it too.
    "VIDIOC_ENUM_FMT/FRAMESIZES/FRAMEINTERVALS": "fmtdesc.description mismatch",
    # uvcvideo starts streaming with no buffer queued (vb2 min_buffers_needed 0): every UVC camera fails these.
    "MMAP (no poll)": "node->streamon(q.g_type()) != EINVAL",
    "MMAP (select)": "node->streamon(q.g_type()) != EINVAL",
    "MMAP (epoll)": "node->streamon(q.g_type()) != EINVAL",
    # The tool gives STREAMOFF 250 ms while another thread blocks in DQBUF, and select() 2 s per frame; a TCG
    # guest on a loaded 2-core host misses them at times (vhci gives unlinked URBs back only on RET_UNLINK).
    "blocking wait": "thread_streamoff.done",
    "USERPTR (select)": "ret == 0",
}


def compliance_failures(output: str) -> dict[str, str]:
    """v4l2-compliance's failed tests, each with its first 'fail:' line."""
    failures, pending = {}, []
    for line in output.splitlines():
        if "fail:" in line:
            pending.append(line.strip())
        m = re.match(r"\s*test (.+?): (OK|FAIL|OK \(Not Supported\))$", line)
        if m:
            if m.group(2) == "FAIL":
                failures[m.group(1)] = pending[0] if pending else ""
            pending = []
    return failures


@pytest.mark.parametrize("transfer", ["iso", "bulk"])
def test_v4l2_compliance_on_uvcvideo_fails_only_where_every_uvc_camera_does(kernel_guest, transfer):
    with attached_camera(kernel_guest, transfer) as att:
        _, out = kernel_guest.sh(f"v4l2-compliance -d {att.node} -s 2>&1", check=False, timeout_s=900)
    total = re.search(r"Total for uvcvideo device \S+: (\d+), Succeeded: (\d+), Failed: (\d+)", out)
    assert total, out[-3000:]
    failures = compliance_failures(out)
    unexplained = {name: why for name, why in failures.items()
                   if KNOWN_COMPLIANCE_FAILURES.get(name, "\0") not in why}
    assert not unexplained, out[-6000:]
    assert int(total.group(1)) >= 50 and int(total.group(3)) == len(failures)


def test_the_kernel_names_the_camera_in_full_with_ids_that_are_no_other_products(kernel_guest):
    with attached_camera(kernel_guest, "iso") as att:
        _, out = kernel_guest.sh(f"cat /sys/class/video4linux/{att.node.removeprefix('/dev/')}/name; "
                                 "v4l2-ctl --list-devices; usbip port")
    assert out.splitlines()[0] == "rollcam emulated UVC camera"  # uvcvideo's 32-byte name, not cut
    assert "rollcam emulated UVC camera (usb-vhci_hcd" in out
    assert "Generic : pid.codes Test PID (1209:0001)" in out  # usb.ids' name for the ID: a test device


def test_others_are_served_while_one_is_attached_and_a_vanished_guest_frees_its_camera(tmp_path):
    """A guest holds camera 1-1 and streams; a host importer streams 1-2 meanwhile. Then the guest's QEMU is
    killed: its connection stays open and unread, and the server frees 1-1 within its send limit."""
    why = guest_module.missing()
    if why:
        pytest.skip(f"the kernel tests need: {why}")
    functions = [UVCFunction(FirmwareProducer(FirmwareCamera("imx219", scene={"scene": "chart", "seed": k})),
                             realtime=True) for k in range(2)]
    limits = ServerLimits(send_timeout_s=3.0, idle_timeout_s=3.0)
    with USBIPServer(functions, "127.0.0.1", 0, limits=limits) as server:
        host, port = server.address
        uri = f"uvc:1209:0001?backend=usbip&usbip={host}:{port}&size=640x480&frames=3&busid="
        g = guest_module.Guest(tmp_path)
        try:
            with g.usbip_port(server.address) as gport:
                g.sh(f"usbip --tcp-port {gport} attach -r 127.0.0.1 -b 1-1")
                node = g.video_node("rollcam")
                g.sh(f"setsid v4l2-ctl -d {node} --stream-mmap=4 --stream-count=100000 --stream-to=/dev/null "
                     "</dev/null >/dev/null 2>&1 &")
                wait_for(lambda: functions[0].streaming, 60, "the guest streaming camera 1-1", every_s=0.1)
                with open_camera(uri + "1-2") as other:  # a second importer, served meanwhile
                    assert len(list(other)) == 3
                assert server.exports["1-1"].owner is not None  # the guest still holds its camera
                g.kill()
        finally:
            g.close()
        wait_for(lambda: server.exports["1-1"].owner is None, 60, "camera 1-1 freed", every_s=0.1)
        with open_camera(uri + "1-1") as again:
            assert len(list(again)) == 3


# ------------------------------------------------------------------------------------ rollcam's sources in the guest
PROBE = Path(__file__).with_name("kernel_probe.py")


def probe(guest, uri: str, count: int) -> dict:
    """Read ``count`` frames from rollcam source ``uri`` with rollcam itself in the guest (``kernel_probe.py``
    under this Python, over the shared root), as a user's program would; returns what each Frame said."""
    name = f"probe-{hashlib.sha1(uri.encode()).hexdigest()[:8]}.json"
    guest.sh(f"{sys.executable} {PROBE} '{uri}' {count} /mnt/{name}", timeout_s=900)
    out = json.loads((guest.xchg / name).read_text())
    (guest.xchg / name).unlink()
    return out


@dataclass(frozen=True)
class RowTimeError:
    """How far a source's row times are from the emulator's, after one clock offset (the guest's monotonic
    clock against the emulator's device clock) is taken out: ``frame_ns`` per frame (first row), ``rows_ns``
    the largest error across one frame's rows beyond its first row's."""

    offset_ns: int
    frame_ns: np.ndarray
    rows_ns: np.ndarray

    @classmethod
    def of(cls, pairs: list[tuple[np.ndarray, np.ndarray]]) -> RowTimeError:
        d = np.stack([host - emu for host, emu in pairs]).astype(np.int64)
        offset = int(np.median(d[:, 0]))
        return cls(offset, d[:, 0] - offset, np.abs(d - d[:, :1]).max(axis=1))

    def summary(self) -> str:
        f = np.abs(self.frame_ns)
        return (f"offset {self.offset_ns} ns; frame error median {np.median(f):.0f} ns, max {f.max()} ns; "
                f"row model error max {self.rows_ns.max()} ns over {len(f)} frames")


@pytest.mark.parametrize("hwtimestamps", [0, 1])
def test_the_v4l2_source_times_every_row_of_the_uvc_camera(kernel_guest, hwtimestamps):
    """``v4l2:/dev/videoN?sensor=imx219`` on the uvcvideo-bound camera (5 fps, which a TCG guest keeps up with):
    each frame matched by its pixels (as OpenCV converts YUYV) to the emulator's, its row times compared with the
    emulator's own. uvcvideo stamps a frame when its first payload arrives (``hwtimestamps=0``, the default) or
    from the payload headers' PTS and SCR (1), which through vhci-hcd has no bus frame number to relate them to."""
    with attached_camera(kernel_guest, "iso") as att:
        kernel_guest.sh(f"echo {hwtimestamps} > /sys/module/uvcvideo/parameters/hwtimestamps")
        got = probe(kernel_guest, f"v4l2:{att.node}?sensor=imx219&size=640x480&fourcc=YUYV&fps=5", 30)
        assert_device_kept(kernel_guest, att)
    assert got["info"]["line_time_ns"] > 0 and got["info"]["shutter"] == "rolling"
    pairs = []
    for f in got["frames"]:
        index = att.recorder.bgr_digests.get(bytes.fromhex(f["sha1"]))
        assert index is not None, f"a v4l2: frame ({f['shape']}) is no frame the emulator sent"
        pairs.append((np.array(f["row_times_ns"]), att.recorder.frames[index].row_times_ns))
    err = RowTimeError.of(pairs)
    print(f"hwtimestamps={hwtimestamps}: {err.summary()}")
    assert err.rows_ns.max() <= 1_000, err.summary()  # the sensor's line time is the emulator's, to the ns
    if hwtimestamps == 0:  # the driver's arrival time: before the program has the frame, within the delivery jitter
        assert all(f["host_ns"] > f["timestamp_ns"] for f in got["frames"])
        assert np.median(np.abs(err.frame_ns)) < 500_000_000, err.summary()


def test_v4l2_and_opencv_sources_read_the_kernels_vivid_camera(kernel_guest):
    """The kernel's own test driver through the same sources: the size asked for, the driver's timestamps
    (the guest's monotonic clock, about one frame period apart; vivid's timestamp can lie a few ms after the
    moment the program has the frame), row times from ``sensor=`` and none without it."""
    kernel_guest.load_module("vivid")
    node = kernel_guest.video_node("vivid")
    index = int(node.removeprefix("/dev/video"))
    for uri, sensor in ((f"v4l2:{node}?size=640x360&sensor=imx219", True), (f"opencv:{index}?size=640x360", False)):
        got = probe(kernel_guest, uri, 12)
        frames = got["frames"]
        assert all(f["shape"] == [360, 640, 3] for f in frames), uri
        stamps = np.array([f["timestamp_ns"] for f in frames])
        hosts = np.array([f["host_ns"] for f in frames])
        assert np.all(np.abs(hosts - stamps) < 2_000_000_000), uri  # the same clock, not another one
        period_ns = 1e9 / got["info"]["fps"]  # vivid's thread runs late and early in a TCG guest: roughly
        assert np.all(np.diff(stamps) > 0) and 0.5 < np.median(np.diff(stamps)) / period_ns < 2, (uri, np.diff(stamps))
        rows = frames[0]["row_times_ns"]
        if sensor:
            # line_time_ns is the nominal line time rounded to the ns; the rows keep its fraction
            assert len(rows) == 360 and abs(rows[-1] - rows[0] - 359 * frames[0]["line_time_ns"]) <= 359, uri
        else:
            assert rows is None and frames[0]["shutter"] == "unknown", uri
