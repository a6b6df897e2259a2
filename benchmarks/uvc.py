"""UVC payload throughput: ``rollcam bench uvc``.

Packs 1920x1080 YUYV frames into UVC payloads (full 12-byte headers: FID, EOF, PTS, SCR) and parses them back
into frames with the host-side parser, for isochronous packets of 1024 and 3072 bytes and 512 KiB bulk
payloads. The target is packing plus parsing at >= 10x the data rate of a 1920x1080 30 fps YUYV stream
(124.4 MB/s, so >= 1.244 GB/s) on 3072-byte isochronous packets, the most headers per byte of the three.
Two whole-path figures are informative: the pyusb read loop through the emulated backend, and streaming over
USB/IP on loopback (both with BGR -> YUYV conversion of a prerendered frame, without rendering), and the
BGR -> YUYV conversion itself: the codec table's kernel against OpenCV's ``cvtColor`` (CPU ms, bytes equal).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from rollcam.emu.uvc.payload import PayloadPacker, PayloadParser

WIDTH, HEIGHT, FPS = 1920, 1080, 30
STREAM_RATE = WIDTH * HEIGHT * 2 * FPS  # bytes/s of 1080p30 YUYV
TARGET_X = 10.0
PAYLOADS = {"iso_1024": 1024, "iso_3072": 3072, "bulk_512k": 512 * 1024}


def codec_throughput(payload_size: int, frames: int, rng: np.random.Generator) -> dict[str, Any]:
    """Pack then parse ``frames`` 1080p YUYV frames: MB/s of each half and of both (median frame times)."""
    data = rng.integers(0, 256, WIDTH * HEIGHT * 2, dtype=np.uint8)
    packer = PayloadPacker(payload_size, 1_000_000_000)
    parser = PayloadParser(1_000_000_000, data.size)
    buf = np.empty(packer.buffer_size(data.size), np.uint8)  # reused, as the streaming endpoint does
    parser.feed_many(packer.pack(data, 0, 0, out=buf))  # warm-up
    packs, parses = [], []
    ok = 0
    for i in range(frames):
        t0 = time.perf_counter()
        batch = packer.pack(data, i * 33_333_333, i * 33_333_333, out=buf)
        t1 = time.perf_counter()
        out = parser.feed_many(batch)
        parses.append(time.perf_counter() - t1)
        packs.append(t1 - t0)
        ok += sum(f.complete and len(f.data) == data.size for f in out)
    # Medians per frame: the machine may be shared, and a median shrugs off the frames another process slowed.
    t_pack, t_parse = float(np.median(packs)), float(np.median(parses))
    both = data.size / (t_pack + t_parse)
    return {"payload_bytes": payload_size, "payloads_per_frame": len(batch), "frames": frames, "frames_ok": ok,
            "pack_mb_s": round(data.size / t_pack / 1e6, 1), "parse_mb_s": round(data.size / t_parse / 1e6, 1),
            "pack_parse_mb_s": round(both / 1e6, 1), "x_1080p30_yuyv": round(both / STREAM_RATE, 2)}


class _StillProducer:
    """A FrameProducer with one prerendered frame: measures the USB path, not the renderer."""

    name = "still"

    def __init__(self, rng: np.random.Generator) -> None:
        from rollcam.emu.uvc.producer import ControlRange
        from rollcam.sim.frame import Frame
        from rollcam.sim.timing import Readout

        img = rng.integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8)
        self._frame = lambda i: Frame(img, "BGR3", i, i * 33_333_333, 0, Readout.TOP_TO_BOTTOM, 10_000_000)
        self._range = ControlRange(100_000, 30_000_000, 10_000_000)

    def sizes(self):
        return [(WIDTH, HEIGHT)]

    def intervals_ns(self, width, height):
        return [33_333_333]

    def configure(self, width, height, interval_ns):
        pass

    def frame_due_ns(self, index):
        return index * 33_333_333

    def frame(self, index):
        return self._frame(index)

    def now_ns(self):
        return 0

    def control_range(self, name):
        return self._range

    def get_control(self, name):
        return self._range.default

    def set_control(self, name, value):
        return value


def _negotiate(control, set_interface, transfer: str) -> Any:
    from rollcam.emu.uvc import constants as C
    from rollcam.emu.uvc.probe import Probe

    control(0x00, C.REQ_SET_CONFIGURATION, 1, 0, b"")
    control(0x21, C.SET_CUR, 0x0100, 1, Probe(bFormatIndex=1, bFrameIndex=1).pack())
    probe = Probe.unpack(bytes(control(0xA1, C.GET_CUR, 0x0100, 1, 48)))
    control(0x21, C.SET_CUR, 0x0200, 1, probe.pack())
    if transfer == "iso":
        set_interface(1, 4)
    return probe


def path_throughput(frames: int, rng: np.random.Generator) -> dict[str, Any]:
    """Frames/s and MB/s of whole 1080p YUYV frames through pyusb (emulated backend) and USB/IP loopback."""
    import usb.core
    from rollcam.emu.usbip import ImportedDevice, USBIPServer
    from rollcam.emu.uvc import UVCFunction
    from rollcam.emu.uvc.pyusb_backend import EmulatedBackend

    out: dict[str, Any] = {}
    size = WIDTH * HEIGHT * 2
    for transfer in ("iso", "bulk"):
        fn = UVCFunction(_StillProducer(rng), fourccs=("YUYV",), transfer=transfer)
        dev = usb.core.find(idVendor=0x1209, backend=EmulatedBackend([fn]))
        probe = _negotiate(dev.ctrl_transfer, dev.set_interface_altsetting, transfer)
        read = 3072 if transfer == "iso" else probe.dwMaxPayloadTransferSize
        parser = PayloadParser(probe.dwClockFrequency, size)
        t0 = time.perf_counter()
        while parser.stats.frames < frames:
            parser.feed(bytes(dev.read(0x81, read)))
        dt = time.perf_counter() - t0
        out[f"pyusb_{transfer}"] = {"fps": round(frames / dt, 1), "mb_s": round(frames * size / dt / 1e6, 1),
                                    "frames_ok": parser.stats.complete}
    fn = UVCFunction(_StillProducer(rng), fourccs=("YUYV",), transfer="iso")
    with USBIPServer([fn], port=0) as srv, ImportedDevice(*srv.address, "1-1") as dev:
        probe = _negotiate(dev.control, lambda i, a: dev.control(0x01, 0x0B, a, i, b""), "iso")
        parser = PayloadParser(probe.dwClockFrequency, size)
        t0 = time.perf_counter()
        while parser.stats.frames < frames:
            parser.feed_batch(*dev.iso_read_batch(0x81, 64, 3072))
        dt = time.perf_counter() - t0
        out["usbip_iso_loopback"] = {"fps": round(frames / dt, 1), "mb_s": round(frames * size / dt / 1e6, 1),
                                     "frames_ok": parser.stats.complete}
    return out


def yuyv_conversion(frames: int, rng: np.random.Generator) -> dict[str, Any]:
    """BGR -> YUYV of a 1080p frame: process CPU ms (median) of the codec table's kernel and of OpenCV's
    ``cvtColor``, in this process on the threads each is given, and whether their bytes are equal."""
    import cv2
    from rollcam.sim.codecs import codec

    bgr = rng.integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8)
    ways = {"rollcam": codec("YUYV").encode, "opencv": lambda a: cv2.cvtColor(a, cv2.COLOR_BGR2YUV_YUYV)}
    out: dict[str, Any] = {"equal": bool(np.array_equal(ways["rollcam"](bgr), ways["opencv"](bgr)))}  # + warm-up
    for name, convert in ways.items():
        cpu = []
        for _ in range(frames):
            t0 = time.process_time()
            convert(bgr)
            cpu.append(time.process_time() - t0)
        out[f"{name}_cpu_ms"] = round(float(np.median(cpu)) * 1e3, 3)
    return out


def run_uvc_bench(frames: int = 30, path_frames: int = 10, seed: int = 0) -> dict[str, Any]:
    """The UVC bench as one JSON document, with its target verdict."""
    rng = np.random.default_rng(seed)
    codec = {name: codec_throughput(size, frames, rng) for name, size in PAYLOADS.items()}
    worst = codec["iso_3072"]["pack_parse_mb_s"]
    return {
        "codec": codec,
        "path": path_throughput(path_frames, rng),
        "yuyv_conversion": yuyv_conversion(frames, rng),
        "target": {"description": "UVC packing plus parsing on 3072-byte isochronous payloads",
                   "value_mb_s": worst, "op": ">=", "limit_mb_s": round(TARGET_X * STREAM_RATE / 1e6, 1),
                   "pass": worst >= TARGET_X * STREAM_RATE / 1e6},
        "stream": f"{WIDTH}x{HEIGHT} YUYV at {FPS} fps = {STREAM_RATE / 1e6:.1f} MB/s",
    }


def format_uvc(doc: dict[str, Any]) -> str:
    """The UVC bench as plain text."""
    lines = [f"stream: {doc['stream']}", f"{'payloads':<12}{'bytes':>9}{'per frame':>10}{'pack MB/s':>11}"
             f"{'parse MB/s':>12}{'both MB/s':>11}{'x stream':>10}"]
    for name, r in doc["codec"].items():
        lines.append(f"{name:<12}{r['payload_bytes']:>9}{r['payloads_per_frame']:>10}{r['pack_mb_s']:>11.1f}"
                     f"{r['parse_mb_s']:>12.1f}{r['pack_parse_mb_s']:>11.1f}{r['x_1080p30_yuyv']:>10.2f}")
    for name, r in doc["path"].items():
        lines.append(f"path {name}: {r['fps']} frames/s, {r['mb_s']} MB/s (incl. BGR->YUYV)")
    y = doc["yuyv_conversion"]
    lines.append(f"1080p BGR->YUYV: rollcam {y['rollcam_cpu_ms']} ms CPU, OpenCV {y['opencv_cpu_ms']} ms CPU, "
                 f"bytes {'equal' if y['equal'] else 'DIFFER'}")
    t = doc["target"]
    lines.append(f"{'PASS' if t['pass'] else 'FAIL'} {t['description']}: {t['value_mb_s']} {t['op']} "
                 f"{t['limit_mb_s']} MB/s")
    return "\n".join(lines)
