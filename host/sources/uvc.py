"""``uvc:VID:PID`` -- a USB Video Class camera through pyusb: real (libusb), emulated in process, or over USB/IP.

Options: ``backend`` (``libusb``, the default: a real camera through pyusb and libusb; ``emu``: the emulated
UVC camera on an in-process pyusb backend; ``usbip``: a camera imported from a USB/IP server), ``usbip``
(HOST:PORT of that server, default 127.0.0.1:3240), ``busid`` (default 1-1), ``format`` (yuyv | nv12 | mjpeg;
default the device's first), ``size`` (WxH; default the first frame size), ``fps`` (nearest offered interval),
``exposure_us`` and ``gain`` (set through the camera terminal and processing unit), ``sensor`` (a hw_config
name: fills line time, readout and row times of each Frame; the emulated camera's sensor), ``decode``
(1: BGR3 frames, the default; 0: the wire format as sent), ``frames`` (stop after N), ``timeout_ms``.
With ``backend=emu`` also ``scene`` and ``seed`` (the emulated camera's options, as ``emu:`` reads them),
``transfer`` (iso | bulk) and ``realtime`` (on | off): the camera is a FirmwareCamera behind the UVC function,
the device object every emulated path shares.

Each Frame's timestamp is the payloads' PTS (start of exposure in the device clock, converted from
dwClockFrequency ticks to integer ns). The PTS has 32 bits: the first frame's timestamp is the device clock
modulo 2**32 ticks (4.29 s at the emulated camera's 1 GHz), except with ``backend=emu``, where the device
clock is read to supply the high bits, and later ones unwrap from it. Damaged frames
(lost payloads, ERR) are dropped and leave a gap in the sequence numbers.
"""

from __future__ import annotations

import time
from collections import deque
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError, DeviceError, DeviceNotFoundError, ProtocolError, SourceError, require
from rollcam.common.lifecycle import Deadline
from rollcam.common.values import parse_bool, usb_id
from rollcam.emu.usbip import ImportedDevice, UrbError
from rollcam.emu.uvc import DeviceIdentity, FirmwareProducer, UVCFunction
from rollcam.emu.uvc import constants as C
from rollcam.emu.uvc.convert import WIRE_FORMATS, decode, wire_layout
from rollcam.emu.uvc.descriptors import parse_streaming
from rollcam.emu.uvc.payload import PayloadParser
from rollcam.emu.uvc.probe import Probe
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.spec import CameraSpec
from rollcam.sim.frame import Frame
from rollcam.sim.hwconfig import SensorConfig, load_sensor
from rollcam.sim.synthetic import resolve_settings
from rollcam.sim.timing import Readout, line_sample_times_ns

from .base import (
    CameraSource,
    SourceURI,
    finite_float,
    parse_host_port,
    parse_size,
    positive_int,
)

OPTIONS = {"backend", "usbip", "busid", "format", "size", "fps", "exposure_us", "gain", "sensor", "decode", "frames",
           "timeout_ms", "scene", "seed", "transfer", "realtime", "insensor"}
EMU_ONLY = {"scene", "seed", "transfer", "realtime", "insensor"}
FORMAT_NAMES = {"yuyv": "YUYV", "nv12": "NV12", "mjpeg": "MJPG", "mjpg": "MJPG"}


def _usb():
    require("usb.core", "pyusb", feature="the uvc: source")
    import usb.core

    return usb


def _parse_ids(uri: SourceURI) -> tuple[int, int]:
    try:
        return usb_id(uri.target)
    except ConfigError as exc:
        raise SourceError(f"source {uri.uri!r}: target {exc}") from None


class _PyUSBLink:
    """Transfers through a pyusb Device (libusb or the emulated backend)."""

    def __init__(self, dev: Any, timeout_ms: int) -> None:
        self.dev, self.timeout_ms = dev, timeout_ms
        self.usb = _usb()

    def control(self, rt: int, req: int, value: int, index: int, data_or_len: bytes | int) -> bytes:
        try:
            out = self.dev.ctrl_transfer(rt, req, value, index, data_or_len, self.timeout_ms)
        except self.usb.core.USBError as exc:
            raise DeviceError(f"control request {req:#04x} ({value:#06x}, {index:#06x}) failed: {exc}") from None
        return b"" if isinstance(out, int) else bytes(out)

    def set_configuration(self, value: int) -> None:
        self.dev.set_configuration(value)

    def set_interface(self, intf: int, alt: int) -> None:
        self.dev.set_interface_altsetting(intf, alt)

    def read_into(self, parser: Any, ep: int, size: int, transfer: str) -> tuple[list, bool]:
        """Read one transfer (one payload) into ``parser``: the frames it completed, and whether data came."""
        try:
            payload = bytes(self.dev.read(ep, size, self.timeout_ms))
        except self.usb.core.USBTimeoutError:
            return [], False
        except self.usb.core.USBError as exc:
            raise DeviceError(f"reading endpoint {ep:#04x} failed: {exc}") from None
        return parser.feed(payload), bool(payload)

    def close(self) -> None:
        self.usb.util.dispose_resources(self.dev)


class _USBIPLink:
    """Transfers through a device imported over USB/IP."""

    ISO_PACKETS = 32

    def __init__(self, dev: Any) -> None:
        self.dev = dev

    def control(self, rt: int, req: int, value: int, index: int, data_or_len: bytes | int) -> bytes:
        try:
            return self.dev.control(rt, req, value, index, data_or_len)
        except UrbError as exc:
            raise DeviceError(f"control request {req:#04x} ({value:#06x}, {index:#06x}) failed: {exc}") from None

    def set_configuration(self, value: int) -> None:
        self.control(0x00, 0x09, value, 0, b"")

    def set_interface(self, intf: int, alt: int) -> None:
        self.control(0x01, 0x0B, alt, intf, b"")

    def read_into(self, parser: Any, ep: int, size: int, transfer: str) -> tuple[list, bool]:
        """Read one URB into ``parser`` (an isochronous URB's packets in one batch)."""
        if transfer == "iso":
            data, lengths = self.dev.iso_read_batch(ep, self.ISO_PACKETS, size)
            return parser.feed_batch(data, lengths), bool(data)
        payload = self.dev.bulk_read(ep, size)
        return parser.feed(payload), bool(payload)

    def close(self) -> None:
        self.dev.close()


def _open_link(uri: SourceURI, vid: int, pid: int, sensor: SensorConfig | None, timeout_ms: int) -> tuple[Any, Any]:
    """The transfer link and, for ``backend=emu``, the emulated function behind it."""
    backend = uri.get("backend", str, "libusb")
    if backend not in ("libusb", "emu", "usbip"):
        raise SourceError(f"source {uri.uri!r}: backend={backend!r} is not one of libusb, emu, usbip")
    extra = EMU_ONLY & set(uri.options)
    if backend != "emu" and extra:
        raise SourceError(f"source {uri.uri!r}: option(s) {sorted(extra)} need backend=emu")
    if backend == "usbip":
        host, port = uri.get("usbip", parse_host_port, ("127.0.0.1", 3240))
        try:
            dev = ImportedDevice(host, port, uri.get("busid", str, "1-1"))
        except (OSError, ValueError, DeviceError, ProtocolError) as exc:
            raise DeviceNotFoundError(f"source {uri.uri!r}: USB/IP import failed: {exc}") from None
        if (dev.info.idVendor, dev.info.idProduct) != (vid, pid):
            dev.close()
            raise DeviceNotFoundError(f"source {uri.uri!r}: the USB/IP device is {dev.info.idVendor:04x}:"
                                      f"{dev.info.idProduct:04x}")
        return _USBIPLink(dev), None
    usb = _usb()
    function = None
    if backend == "emu":
        function, be = _emulated(uri, vid, pid, sensor)
    else:
        import usb.backend.libusb1

        be = usb.backend.libusb1.get_backend()
        if be is None:
            raise DeviceError(f"source {uri.uri!r}: libusb-1.0 was not found (install libusb, e.g. apt install "
                              "libusb-1.0-0, or use backend=emu / backend=usbip)")
    dev = usb.core.find(idVendor=vid, idProduct=pid, backend=be)
    if dev is None:
        raise DeviceNotFoundError(f"source {uri.uri!r}: no USB device {vid:04x}:{pid:04x} found")
    return _PyUSBLink(dev, timeout_ms), function


def _emulated(uri: SourceURI, vid: int, pid: int, sensor: SensorConfig | None) -> tuple[Any, Any]:
    """The UVC function of an emulated camera: the same FirmwareCamera (from the same option table) the emu:
    source and ``rollcam emulate`` use, behind a FirmwareProducer."""
    from rollcam.emu.uvc.pyusb_backend import EmulatedBackend  # needs pyusb

    options = {k: uri.options[k] for k in ("scene", "seed", "size", "insensor") if k in uri.options}
    spec = CameraSpec.from_options(sensor or load_sensor("imx219"), options, f"source {uri.uri!r}", SourceError)
    function = UVCFunction(FirmwareProducer(FirmwareCamera(spec)), identity=DeviceIdentity(vendor_id=vid,
                           product_id=pid), transfer=uri.get("transfer", str, "iso"),
                           realtime=uri.get("realtime", parse_bool, False))
    return function, EmulatedBackend([function])


class UVCSource(CameraSource):
    """Frames from a UVC camera: probe/commit negotiation, then payloads parsed into Frames."""

    def __init__(self, uri: SourceURI) -> None:
        self.uri = uri.uri
        uri.take(set(), OPTIONS)
        vid, pid = _parse_ids(uri)
        try:
            self.sensor = load_sensor(uri.options["sensor"]) if "sensor" in uri.options else None
        except ConfigError as exc:
            raise SourceError(f"source {uri.uri!r}: {exc}") from None
        self.limit = uri.get("frames", positive_int)
        self.decode = bool(uri.get("decode", int, 1))
        self.timeout_ms = uri.get("timeout_ms", positive_int, 5000)
        self.link, self.function = _open_link(uri, vid, pid, self.sensor, self.timeout_ms)
        if self.function is not None and self.sensor is None:
            self.sensor = self.function.producer.camera.sensor
        self.index = 0
        self._pending: deque = deque()
        try:
            head = self.link.control(0x80, 0x06, 0x0200, 0, 9)
            config = self.link.control(0x80, 0x06, 0x0200, 0, int.from_bytes(head[2:4], "little"))
            self.stream = parse_streaming(config)
            self.link.set_configuration(config[5])
            self._negotiate(uri)
        except (DeviceError, ProtocolError) as exc:
            self.close()
            raise SourceError(f"source {uri.uri!r}: negotiation failed: {exc}") from None
        except BaseException:  # a bad option found while negotiating: release the device all the same
            self.close()
            raise

    def _negotiate(self, uri: SourceURI) -> None:
        s = self.stream
        want = uri.get("format", str)
        fi = 1
        if want is not None:
            fourcc = FORMAT_NAMES.get(want.lower())
            names = [f.fourcc for f in s.formats]
            if fourcc not in names:
                raise SourceError(f"source {uri.uri!r}: format={want!r}; the camera offers {names}")
            fi = names.index(fourcc) + 1
        fmt = s.formats[fi - 1]
        size = uri.get("size", parse_size)
        sizes = [(f.width, f.height) for f in fmt.frames]
        if size is not None and size not in sizes:
            raise SourceError(f"source {uri.uri!r}: size={size[0]}x{size[1]} is not offered; sizes: {sizes}")
        ri = sizes.index(size) + 1 if size else 1
        intervals = fmt.frames[ri - 1].intervals_100ns
        fps = uri.get("fps", finite_float)
        default = fmt.frames[ri - 1].default_100ns or intervals[0]
        interval = default if fps is None else min(intervals, key=lambda i: abs(i - 1e7 / fps))
        vs = s.interface
        length = int.from_bytes(self.link.control(0xA1, C.GET_LEN, C.VS_PROBE_CONTROL << 8, vs, 2), "little")
        length = length if length in C.PROBE_LENGTHS else C.PROBE_LEN_11
        probe = Probe(bmHint=1, bFormatIndex=fi, bFrameIndex=ri, dwFrameInterval=interval)
        self.link.control(0x21, C.SET_CUR, C.VS_PROBE_CONTROL << 8, vs, probe.pack(length))
        probe = Probe.unpack(self.link.control(0xA1, C.GET_CUR, C.VS_PROBE_CONTROL << 8, vs, length))
        self.link.control(0x21, C.SET_CUR, C.VS_COMMIT_CONTROL << 8, vs, probe.pack(length))
        self.probe, self.fourcc = probe, fmt.fourcc
        self.width, self.height = sizes[ri - 1]
        for name, selector, unit, n, scale in (("exposure_us", C.CT_EXPOSURE_TIME_ABSOLUTE_CONTROL,
                                                C.TERMINAL_CAMERA, 4, 0.01), ("gain", C.PU_GAIN_CONTROL,
                                                                              C.UNIT_PROCESSING, 2, 100)):
            value = uri.get(name, finite_float)
            if value is not None:
                self.link.control(0x21, C.SET_CUR, selector << 8, unit << 8, round(value * scale).to_bytes(n, "little"))
        exp = self.link.control(0xA1, C.GET_CUR, C.CT_EXPOSURE_TIME_ABSOLUTE_CONTROL << 8, C.TERMINAL_CAMERA << 8, 4)
        self.exposure_ns = int.from_bytes(exp, "little") * 100_000
        if s.transfer == "iso":
            fitting = sorted((mps, alt) for alt, mps in s.alt_packet_sizes.items()
                             if alt and mps >= probe.dwMaxPayloadTransferSize)
            mps, alt = fitting[0] if fitting else max((m, a) for a, m in s.alt_packet_sizes.items())
            self.read_size = mps
            self.link.set_interface(vs, alt)
        else:
            self.read_size = probe.dwMaxPayloadTransferSize
        self.clock_hz = probe.dwClockFrequency or s.clock_hz or 1_000_000_000
        # Sizes and shapes from rollcam.sim.formats; None (frames of any size complete, passed on flat) for MJPEG
        # and formats of a real camera this source does not know.
        self.layout = wire_layout(self.fourcc) if self.fourcc in WIRE_FORMATS else None
        size = None if self.layout is None else self.layout.sizeimage(self.width, self.height)
        self.parser = PayloadParser(self.clock_hz, size)
        self._timing()

    def _timing(self) -> None:
        """Row timing from the sensor description (exact exposure and line time when the sensor is known)."""
        self.timing = None
        self.readout = Readout.TOP_TO_BOTTOM
        self.shutter = "unknown"
        if self.sensor is None:
            return
        try:
            st = resolve_settings(self.sensor, size=(self.width, self.height), fps=1e7 / self.probe.dwFrameInterval,
                                  exposure_ns=self.exposure_ns)
        except ConfigError:
            return
        self.timing, self.readout, self.shutter = st.timing, st.readout, st.shutter
        self.exposure_ns = st.exposure_ns
        self.n_lines = st.n_lines

    def read(self) -> Frame | None:
        """The next complete frame, or None after ``frames=N``."""
        self._check_open()
        if self.limit is not None and self.index >= self.limit:
            return None
        deadline = Deadline(self.timeout_ms / 1000)  # restarted whenever data comes
        while True:
            while self._pending:
                parsed = self._pending.popleft()
                frame = self._frame(parsed) if parsed.complete and not parsed.error else None
                if frame is not None:
                    self.index += 1
                    return frame
            if self.function is not None and self.parser.stats.frames == 0:
                # In process the device clock can be read: it gives the first PTS its high bits.
                self.parser.reference_ns = self.function.producer.now_ns()
            # One isochronous URB can end several small frames: keep them all, in order.
            parsed, got = self.link.read_into(self.parser, self.stream.endpoint, self.read_size, self.stream.transfer)
            self._pending.extend(parsed)
            if got:
                deadline.restart()
            elif deadline.expired:
                raise DeviceError(f"source {self.uri!r}: no data from the camera for {self.timeout_ms} ms")

    def _frame(self, parsed: Any) -> Frame | None:
        w, h, fourcc = self.width, self.height, self.fourcc
        try:
            if self.decode:
                data, fmt = decode(parsed.data, fourcc, w, h), "BGR3"
            else:
                raw = np.frombuffer(parsed.data, np.uint8)
                data = raw if self.layout is None else raw.reshape(self.layout.shape(w, h))
                fmt = fourcc
        except ProtocolError:
            self.parser.stats.errors += 1
            return None
        t0 = parsed.pts_ns if parsed.pts_ns is not None else time.monotonic_ns()
        rows = None
        line_ns = 0
        if self.timing is not None:
            rolling = self.shutter == "rolling"
            rows = line_sample_times_ns(t0 + self.exposure_ns // 2, self.n_lines, self.timing if rolling else None,
                                        self.readout)
            line_ns = self.timing.line_time_ns if rolling else 0
        meta = {"wire_format": fourcc, "pts": parsed.pts, "scr": parsed.scr, "payloads": parsed.payloads}
        return Frame(data=data, format=fmt, size=(w, h), sequence=parsed.index, timestamp_ns=int(t0),
                     line_time_ns=line_ns, readout=self.readout, exposure_ns=self.exposure_ns, shutter=self.shutter,
                     row_times_ns=rows, meta=meta, insensor=self._insensor(parsed, int(t0), line_ns))

    def _insensor(self, parsed: Any, t0: int, line_ns: int) -> tuple[Any, ...]:
        """The in-sensor result in the frame's payload header (``emu.uvc.metadata``), if the camera sent one."""
        if not parsed.extra or parsed.pts is None:
            return ()
        from rollcam.emu.uvc.metadata import decode as decode_item
        from rollcam.emu.uvc.metadata import to_result

        item = decode_item(parsed.extra, self.clock_hz)
        if item is None:
            return ()
        return (to_result(item, parsed.pts, t0, self.clock_hz, parsed.index, line_time_ns=line_ns,
                          readout=self.readout.value, exposure_ns=self.exposure_ns),)

    def info(self) -> dict[str, Any]:
        """Negotiated format, size, interval, clock, and the parser's counts."""
        st = self.parser.stats
        return {"uri": self.uri, "format": self.fourcc, "width": self.width, "height": self.height,
                "fps": 1e7 / self.probe.dwFrameInterval, "transfer": self.stream.transfer, "clock_hz": self.clock_hz,
                "sensor": None if self.sensor is None else self.sensor.name, "shutter": self.shutter,
                "exposure_ns": self.exposure_ns, "frames_parsed": st.frames, "frames_damaged": st.frames - st.complete,
                "bad_headers": st.bad_headers}

    def _close(self) -> None:
        """Release the device."""
        if getattr(self, "link", None) is not None:
            try:
                self.link.close()
            finally:
                if self.function is not None:
                    self.function.close()  # the emulated camera belongs to this source


def open_source(uri: SourceURI) -> UVCSource:
    """Scheme entry point for ``uvc:``."""
    return UVCSource(uri)
