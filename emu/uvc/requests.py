"""UVC class-specific requests: probe/commit negotiation and the camera terminal / processing unit controls.

``VideoControls`` answers SET_CUR and GET_CUR/MIN/MAX/RES/LEN/INFO/DEF for the controls the descriptors
advertise, maps them onto the producer's controls, and keeps the probe and commit state. Every refused
request raises ``Stall`` after setting the code VC_REQUEST_ERROR_CODE_CONTROL reports (UVC 1.5 section
4.2.1.2), so a malformed request costs the host a STALL and nothing else.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from rollcam.common.errors import DeviceError, ProtocolError
from rollcam.sim.codecs import JPEG_QUALITY
from rollcam.sim.formats import pixel_format

from . import constants as C
from .convert import wire_layout
from .descriptors import HEADER_MAX, StreamFormat
from .probe import Probe
from .producer import FrameProducer

EXPOSURE_UNIT_NS = 100_000  # CT_EXPOSURE_TIME_ABSOLUTE counts 100 us
DEFAULT_QUALITY = JPEG_QUALITY * 100  # wCompQuality, 1..10000
_MJPEG_BOUND = pixel_format("YUYV")  # dwMaxVideoFrameSize of MJPEG: an uncompressed 4:2:2 frame's size


class Stall(DeviceError):
    """The device answered a control request with a STALL handshake; ``code`` is the request error code."""

    def __init__(self, message: str, code: int = C.ERR_UNKNOWN) -> None:
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class _Scalar:
    """An integer control: its length, GET_INFO bits and how each request reads or writes it."""

    length: int
    info: int
    get: Callable[[VideoControls, int], int]
    set: Callable[[VideoControls, int], None] | None = None


def _exposure_get(vc: VideoControls, req: int) -> int:
    r = vc.producer.control_range("exposure_ns")
    return {C.GET_CUR: round(vc.producer.get_control("exposure_ns") / EXPOSURE_UNIT_NS),
            C.GET_MIN: max(-(-r.minimum // EXPOSURE_UNIT_NS), 1), C.GET_MAX: r.maximum // EXPOSURE_UNIT_NS,
            C.GET_RES: 1, C.GET_DEF: round(r.default / EXPOSURE_UNIT_NS)}[req]


def _gain_get(vc: VideoControls, req: int) -> int:
    r = vc.producer.control_range("gain")
    return {C.GET_CUR: vc.producer.get_control("gain"), C.GET_MIN: r.minimum, C.GET_MAX: r.maximum,
            C.GET_RES: r.step, C.GET_DEF: r.default}[req]


def _ranged_set(name: str, getter: Callable[[VideoControls, int], int], scale: int) -> Callable:
    def write(vc: VideoControls, value: int) -> None:
        lo, hi = getter(vc, C.GET_MIN), getter(vc, C.GET_MAX)
        if not lo <= value <= hi:
            raise Stall(f"{name} {value!r} outside {lo}..{hi}", C.ERR_OUT_OF_RANGE)
        vc.producer.set_control(name, value * scale)
    return write


def _ae_mode_get(vc: VideoControls, req: int) -> int:
    if req in (C.GET_MIN, C.GET_MAX):
        raise Stall("AE mode has no GET_MIN/GET_MAX", C.ERR_INVALID_REQUEST)
    return 0x01  # manual only: CUR, DEF and the RES bitmap of supported modes


def _ae_mode_set(vc: VideoControls, value: int) -> None:
    if value != 0x01:
        raise Stall(f"AE mode {value:#x} is not supported (manual 0x01 only)", C.ERR_INVALID_VALUE)


def _fixed_zero(vc: VideoControls, req: int) -> int:
    return 1 if req == C.GET_RES else 0


def _error_get(vc: VideoControls, req: int) -> int:
    if req != C.GET_CUR:
        raise Stall("the request error code control answers GET_CUR only", C.ERR_INVALID_REQUEST)
    return vc.error_code


SCALARS: dict[tuple[int, int, int], _Scalar] = {
    (0, C.UNIT_VC, C.VC_REQUEST_ERROR_CODE_CONTROL): _Scalar(1, C.INFO_GET, _error_get),
    (0, C.TERMINAL_CAMERA, C.CT_AE_MODE_CONTROL): _Scalar(1, C.INFO_GET | C.INFO_SET, _ae_mode_get, _ae_mode_set),
    (0, C.TERMINAL_CAMERA, C.CT_EXPOSURE_TIME_ABSOLUTE_CONTROL): _Scalar(
        4, C.INFO_GET | C.INFO_SET, _exposure_get, _ranged_set("exposure_ns", _exposure_get, EXPOSURE_UNIT_NS)),
    (0, C.UNIT_PROCESSING, C.PU_GAIN_CONTROL): _Scalar(2, C.INFO_GET | C.INFO_SET, _gain_get,
                                                       _ranged_set("gain", _gain_get, 1)),
    # Not a knob of this camera and not in rollcam's descriptors; Linux 6.1's UVC gadget function advertises it
    # whatever its configfs says (bmControls read-only), so a host asks: a read-only 0, not a STALL per query.
    (0, C.UNIT_PROCESSING, C.PU_BRIGHTNESS_CONTROL): _Scalar(2, C.INFO_GET, _fixed_zero),
}
"""(interface, entity, selector) -> control. Entity 0 on interface 0 is the VideoControl interface itself."""

UNITS = {(0, C.UNIT_VC), (0, C.TERMINAL_CAMERA), (0, C.UNIT_PROCESSING), (0, C.TERMINAL_OUTPUT), (1, 0)}


@dataclass(frozen=True)
class Committed:
    """A committed stream: format, frame size and the producer's exact frame period."""

    probe: Probe
    fourcc: str
    width: int
    height: int
    interval_ns: int
    payload_size: int
    jpeg_quality: int


class VideoControls:
    """State and answers of the class-specific requests of one UVC function."""

    def __init__(self, producer: FrameProducer, formats: tuple[StreamFormat, ...], intervals_ns: dict,
                 clock_hz: int, payload_size: Callable[[int, int], int]) -> None:
        self.producer = producer
        self.formats = formats
        self.intervals_ns = intervals_ns  # (format index, frame index) -> ((100 ns units, exact ns), ...)
        self.clock_hz = clock_hz
        self.payload_size = payload_size  # (frame bytes, interval_ns) -> dwMaxPayloadTransferSize
        self.error_code = C.ERR_NONE
        self.streaming = False  # set by the device: commit is refused while the stream runs
        self.probe = self._negotiate(self.default_probe())
        self.committed: Committed | None = None

    # -------------------------------------------------------------------------------- dispatch
    def request(self, request: int, interface: int, entity: int, selector: int, length: int,
                data: bytes) -> bytes:
        """Answer one class request (GET_* returns the bytes; SET_CUR returns b''); refused ones raise Stall."""
        try:
            out = self._dispatch(request, interface, entity, selector, length, data)
        except Stall as exc:
            self.error_code = exc.code
            raise
        self.error_code = C.ERR_NONE
        return out

    def _dispatch(self, req: int, intf: int, entity: int, sel: int, length: int, data: bytes) -> bytes:
        if req not in C.REQUEST_NAMES:
            raise Stall(f"request {req:#04x} is not a UVC request", C.ERR_INVALID_REQUEST)
        if (intf, entity) not in UNITS:
            raise Stall(f"no unit {entity} on interface {intf}", C.ERR_INVALID_UNIT)
        if intf == 1 and sel in (C.VS_PROBE_CONTROL, C.VS_COMMIT_CONTROL):
            return self._stream_control(req, sel, length, data)
        ctl = SCALARS.get((intf, entity, sel))
        if ctl is None:
            raise Stall(f"unit {entity} has no control {sel:#04x}", C.ERR_INVALID_CONTROL)
        if req == C.GET_INFO:
            return self._sized(bytes((ctl.info,)), length, 1)
        if req == C.GET_LEN:
            return self._sized(ctl.length.to_bytes(2, "little"), length, 2)
        if req == C.SET_CUR:
            if ctl.set is None:
                raise Stall(f"control {sel:#04x} of unit {entity} is read-only", C.ERR_INVALID_REQUEST)
            if len(data) != ctl.length:
                raise Stall(f"SET_CUR with {len(data)} bytes; the control has {ctl.length}", C.ERR_INVALID_VALUE)
            ctl.set(self, int.from_bytes(data, "little"))
            return b""
        return self._sized(ctl.get(self, req).to_bytes(ctl.length, "little"), length, ctl.length)

    @staticmethod
    def _sized(payload: bytes, length: int, want: int) -> bytes:
        if length != want:
            raise Stall(f"wLength {length} for a {want}-byte control", C.ERR_INVALID_REQUEST)
        return payload

    # ----------------------------------------------------------------------------- probe/commit
    def _stream_control(self, req: int, sel: int, length: int, data: bytes) -> bytes:
        if req == C.GET_INFO:
            return self._sized(bytes((C.INFO_GET | C.INFO_SET,)), length, 1)
        if req == C.GET_LEN:
            return self._sized(C.PROBE_LEN_15.to_bytes(2, "little"), length, 2)
        if req == C.SET_CUR:
            if len(data) not in C.PROBE_LENGTHS:
                raise Stall(f"probe/commit SET_CUR with {len(data)} bytes; expected one of {C.PROBE_LENGTHS}",
                            C.ERR_INVALID_VALUE)
            try:
                probe = Probe.unpack(data)
            except ProtocolError as exc:
                raise Stall(str(exc), C.ERR_INVALID_VALUE) from None
            if sel == C.VS_PROBE_CONTROL:
                self.probe = self._negotiate(probe)
            else:
                self._commit(probe)
            return b""
        if length not in C.PROBE_LENGTHS:
            raise Stall(f"probe/commit read of {length} bytes; expected one of {C.PROBE_LENGTHS}",
                        C.ERR_INVALID_REQUEST)
        if sel == C.VS_COMMIT_CONTROL:
            if req != C.GET_CUR:
                raise Stall("the commit control answers GET_CUR only", C.ERR_INVALID_REQUEST)
            return (self.committed.probe if self.committed else self.probe).pack(length)
        table = {C.GET_CUR: lambda: self.probe, C.GET_DEF: lambda: self._negotiate(self.default_probe()),
                 C.GET_MIN: lambda: self._negotiate(self.probe.with_(dwFrameInterval=1)),
                 C.GET_MAX: lambda: self._negotiate(self.probe.with_(dwFrameInterval=0xFFFFFFFF)),
                 C.GET_RES: lambda: Probe(dwFrameInterval=1)}
        return table[req]().pack(length)

    def default_probe(self) -> Probe:
        """Format 1, frame 1, its default interval."""
        return Probe(bmHint=1, bFormatIndex=1, bFrameIndex=1,
                     dwFrameInterval=self.formats[0].frames[0].default_100ns, wCompQuality=DEFAULT_QUALITY)

    def _lookup(self, probe: Probe) -> tuple[StreamFormat, int, int]:
        fi, ri = probe.bFormatIndex, probe.bFrameIndex
        if not 1 <= fi <= len(self.formats):
            raise Stall(f"bFormatIndex {fi} outside 1..{len(self.formats)}", C.ERR_OUT_OF_RANGE)
        fmt = self.formats[fi - 1]
        if not 1 <= ri <= len(fmt.frames):
            raise Stall(f"bFrameIndex {ri} outside 1..{len(fmt.frames)} of format {fi}", C.ERR_OUT_OF_RANGE)
        return fmt, fi, ri

    def _negotiate(self, probe: Probe) -> Probe:
        """The device's answer to a probe: nearest offered interval, sizes and clock filled in."""
        fmt, fi, ri = self._lookup(probe)
        offered = self.intervals_ns[(fi, ri)]
        units = probe.dwFrameInterval or offered[0][0]
        iv, ns = min(offered, key=lambda o: (abs(o[0] - units), o[0]))
        size = fmt.frames[ri - 1]
        raw = (wire_layout(fmt.fourcc) or _MJPEG_BOUND).sizeimage(size.width, size.height)
        quality = probe.wCompQuality if 1 <= probe.wCompQuality <= 10000 else DEFAULT_QUALITY
        return probe.with_(dwFrameInterval=iv, dwMaxVideoFrameSize=raw, wCompQuality=quality,
                           dwMaxPayloadTransferSize=self.payload_size(raw, ns), dwClockFrequency=self.clock_hz,
                           bmFramingInfo=0x03, bPreferedVersion=1, bMinVersion=1, bMaxVersion=1, wDelay=0)

    def _commit(self, probe: Probe) -> None:
        if self.streaming:
            raise Stall("commit while streaming; select alternate setting 0 first", C.ERR_WRONG_STATE)
        fmt, fi, ri = self._lookup(probe)
        match = [ns for iv, ns in self.intervals_ns[(fi, ri)] if iv == probe.dwFrameInterval]
        if not match:
            raise Stall(f"dwFrameInterval {probe.dwFrameInterval} is not offered for format {fi} frame {ri}",
                        C.ERR_INVALID_VALUE)
        size = fmt.frames[ri - 1]
        try:
            self.producer.configure(size.width, size.height, match[0])
        except DeviceError as exc:
            raise Stall(str(exc), C.ERR_INVALID_VALUE) from None
        negotiated = self._negotiate(probe)
        quality = max(1, min(100, round(negotiated.wCompQuality / 100)))
        payload = max(negotiated.dwMaxPayloadTransferSize, HEADER_MAX + 1)
        self.committed = Committed(negotiated, fmt.fourcc, size.width, size.height, match[0], payload, quality)
