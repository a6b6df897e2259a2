"""The kernel side of the emulated V4L2 device (as vivid is to a real camera): ``ioctl(request, arg)``.

``EmuDriver`` answers the VIDIOC requests of ``raw.Ioctl`` for one FirmwareCamera with the kernel's
semantics and errnos. Frames are paced in real time (a ``FramePump`` fills the buffer band by band at the
lines' device times) or made as fast as possible (each DQBUF renders the next frame). A
``rollcam.common.faults.FaultPlan`` injects what vivid's error-injection controls do: dropped buffers (a gap
in the sequence numbers), the ERROR flag, one-shot ioctl errors, a disconnect (ENODEV until the device is
closed, then it is connected again) and sequence and timestamp wrap, and the lab faults: frame-counter
rewrite, freeze and skip in ``sequence``, grey, black and frozen images, and sensor register resets
(``rollcam.firmware.labfaults``); ``fault_stats`` counts what was injected.
"""

from __future__ import annotations

import errno
import threading
from collections.abc import Callable
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError, DeviceError
from rollcam.common.faults import REQUESTS, FaultInjector, FaultPlan
from rollcam.common.lifecycle import Stats
from rollcam.emu.pump import FramePump
from rollcam.firmware.camera import FirmwareCamera, FramePlan, default_interval
from rollcam.firmware.controls import CONTROLS
from rollcam.firmware.imaging import mjpeg_quality
from rollcam.firmware.labfaults import FrameFaults
from rollcam.firmware.pixfmt import device_format
from rollcam.sim.codecs import transcode
from rollcam.sim.formats import YUV_PACKINGS
from rollcam.sim.frame import Frame

from . import ctrls, raw
from .ctrls import CID_TO_CONTROL
from .queue import BufferQueue, BufferState, Slot, V4L2Error

CTRL_NAMES = {"exposure": "Exposure", "analogue_gain": "Analogue Gain", "digital_gain": "Digital Gain",
              "vblank": "Vertical Blanking", "hblank": "Horizontal Blanking", "pixel_rate": "Pixel Rate",
              "test_pattern": "Test Pattern", "hflip": "Horizontal Flip", "vflip": "Vertical Flip"}
_CTRL_TYPES = {"int": raw.CtrlType.INTEGER, "bool": raw.CtrlType.BOOLEAN, "menu": raw.CtrlType.MENU}


@dataclass
class DriverStats(Stats):
    """What the driver did with frames: delivered, and dropped because no buffer was queued (injected faults
    are counted in ``EmuDriver.fault_stats``)."""

    delivered: int = 0
    dropped_no_buffer: int = 0


class EmuDriver:
    """Driver state of one emulated /dev/videoN: format, buffer queue, streaming, faults, statistics."""

    buf_type = raw.BufType.VIDEO_CAPTURE
    requests: frozenset[str] | None = None  # None: every request of the ioctl core

    def __init__(self, camera: FirmwareCamera, *, realtime: bool = True, bands: int = 8,
                 faults: FaultPlan | str | None = None, rt_priority: int | None = None,
                 alloc: Callable[[int, int], np.ndarray] | None = None) -> None:
        self.camera = camera
        self.realtime = realtime
        self.rt_priority = rt_priority
        self.bands = bands
        self.faults = FaultPlan.of(faults)
        self.injector = FaultInjector(self.faults)
        self.fault_stats = self.injector.stats
        self.frame_faults = FrameFaults(self.injector, camera, on_reset=self._note_reset)
        self._reset_lock = threading.Lock()
        self._reset_before: dict[int, Any] | None = None  # the controls before a register reset not yet announced
        self.queue = BufferQueue(alloc=alloc)
        self.on_change: Callable[[], None] | None = None  # called (pump thread) after a buffer completes
        self.ctrl_defaults = {name: info["value"] for name, info in camera.controls().items()}
        self.pump: FramePump | None = None
        self.seq0 = 0
        self.ts0: int | None = None  # the stream's first timestamp (where an injected timestamp wrap counts from)
        self.stats = DriverStats()
        self._filling: tuple[int, Slot, np.ndarray] | None = None
        self.meta: Any = None  # the metadata node's driver (``meta.MetaDriver``), filled as each buffer completes
        modes = camera.sizes()
        self.sizes = modes if camera.size in modes else [*modes, camera.size]
        """Frame sizes the device offers: the sensor's modes and, when its camera was made with a size that is no
        mode (``size=640x480`` on an imx477), that size too (the default mode's readout scaled to it, as a bridge's
        scaler gives a size the sensor has no mode for), for as long as it lives, so a client can set it again."""

    @property
    def fmt(self) -> raw.PixFormat:
        """The current format (G_FMT): the camera's size and fourcc, so a flip's new Bayer order shows here."""
        return _pix_format(*self.camera.size, self.camera.pixel_format)

    def ioctl(self, request: raw.Ioctl | str, arg: Any = None) -> Any:
        """Run one VIDIOC request; failures raise V4L2Error with the kernel's errno."""
        request = raw.Ioctl(request)
        self.admit(request)
        try:
            return _HANDLERS[request](self, arg)
        except V4L2Error:
            raise
        except ConfigError as exc:
            raise V4L2Error(errno.EINVAL, f"{request.value}: {exc}") from None
        except DeviceError as exc:
            raise V4L2Error(errno.EBUSY, f"{request.value}: {exc}") from None

    def admit(self, request: raw.Ioctl) -> None:
        """What every request meets first: ENODEV once unplugged, then the fault plan's injected errno (paths
        that answer a request without ``ioctl``, such as the preload node's controls, call it too)."""
        if self.queue.disconnected:
            raise V4L2Error(errno.ENODEV, f"{request.value}: device disconnected")
        name = request.value.removeprefix("VIDIOC_").lower()
        injected = self.injector.request(name) if name in REQUESTS else None
        if injected is not None:
            raise V4L2Error(injected, f"{request.value}: injected error")

    def _note_reset(self) -> None:
        """An injected register reset is about to happen (on the thread making frames): keep the controls as they
        were, for the node to announce what changed (V4L2_EVENT_CTRL) at its next request."""
        before = ctrls.controls(self)
        with self._reset_lock:
            if self._reset_before is None:
                self._reset_before = before

    def take_reset(self) -> dict[int, Any] | None:
        """The controls before the register resets since the last call (None when there was none)."""
        with self._reset_lock:
            before, self._reset_before = self._reset_before, None
            return before

    def disconnect(self) -> None:
        """Unplug: stop producing; every call and waiter from now on gets ENODEV."""
        try:
            self._stop_pump()
        finally:
            self.camera.stream_off()
            self.queue.disconnect()

    def close(self) -> None:
        """Release the device (stream off, buffers freed); a disconnected device is connected again, as vivid's
        is once its last file handle closes. Idempotent."""
        try:
            self._stop_pump()
        finally:
            self.camera.stream_off()
            self.queue.stop()
            self.queue.disconnected = False

    # ------------------------------------------------------------------------------------- frame delivery
    def _stop_pump(self) -> None:
        """Stop the pump; what stopped it early (if anything did and nobody saw it yet) is raised as EIO."""
        pump, self.pump = self.pump, None
        if pump is not None:
            try:
                pump.close()
            except DeviceError as exc:
                raise V4L2Error(errno.EIO, f"the frame pump stopped: {exc.__cause__!r}") from exc

    def on_band(self, frame: Frame, plan: FramePlan, band: int, n_bands: int) -> None:
        """Pump sink: copy the band's lines into the buffer being filled (taking one at the first band)."""
        if band == 0:
            slot = self.queue.take()
            self._filling = None if slot is None else (plan.seq, slot, self._payload(frame))
        if self._filling is None or self._filling[0] != plan.seq:
            return
        _, slot, payload = self._filling
        fmt = self.fmt
        readout = self.camera.spec.settings.readout
        layout = device_format(fmt.pixelformat).layout
        if layout is not None and not readout.by_column:
            first, end = plan.schedule.band_lines(band, n_bands)
            if readout.reversed:
                first, end = fmt.height - end, fmt.height - first
            for lo, hi in layout.line_spans(first, end, fmt.width, fmt.height):
                slot.memory[lo:hi] = payload[lo:hi]
        elif band == n_bands - 1:
            slot.memory[: payload.size] = payload

    def on_frame(self, frame: Frame, plan: FramePlan) -> None:
        """Pump sink: the frame is complete; deliver (or drop) the buffer."""
        if self._filling is None or self._filling[0] != plan.seq:
            self.stats.dropped_no_buffer += 1
            return
        _, slot, payload = self._filling
        self._filling = None
        self._deliver(slot, frame, payload.size)

    def _payload(self, frame: Frame) -> np.ndarray:
        frame = self.frame_faults.apply(frame, frame.sequence)
        fourcc = self.fmt.pixelformat
        # A raw frame is already in its fourcc's layout (the sensor's samples); renders are encoded.
        data = transcode(frame, fourcc, quality=mjpeg_quality(self.camera.spec))
        return np.ascontiguousarray(data).reshape(-1).view(np.uint8)

    def _deliver(self, slot: Slot, frame: Frame, size: int) -> None:
        """Complete ``slot`` with ``frame`` (faults decided by the device frame number: reproducible in real
        time too, whichever frames the application had buffers for)."""
        inj = self.injector
        if inj and inj.disconnect_due(self.stats.delivered):
            self.queue.disconnect()  # unplugged before this frame: it is lost, as on a real unplug
            if self.on_change is not None:
                self.on_change()
            return
        if inj.hit("drop", frame.sequence):
            self.queue.give_back(slot)  # vivid: never returned; the sequence number shows the gap
            return
        t_ns = self.camera.host_ns(frame.timestamp_ns)
        if self.ts0 is None:
            self.ts0 = t_ns
        sequence = inj.sequence(frame.sequence - self.seq0)
        timestamp_ns = self.faults.timestamp_ns(t_ns, self.ts0)
        self.queue.complete(slot, bytesused=size, sequence=sequence, timestamp_ns=timestamp_ns,
                            error=inj.hit("error", frame.sequence))
        self.stats.delivered += 1
        if self.meta is not None:
            self.meta.deliver(frame, sequence, timestamp_ns)
        if self.on_change is not None:
            self.on_change()

    def produce_now(self) -> bool:
        """As-fast-as-possible mode: render the next frame into the oldest queued buffer; False if none is due."""
        slot = self.queue.take()
        if slot is None:
            return False
        plan = self.camera.plan_next()
        if plan is None:
            self.queue.give_back(slot)
            return False
        frame = self.camera.render(plan)
        payload = self._payload(frame)
        slot.memory[: payload.size] = payload
        self._deliver(slot, frame, payload.size)
        return True


def _pix_format(width: int, height: int, fourcc: str) -> raw.PixFormat:
    """G_FMT's answer. The colorimetry says what the codec table (``rollcam.sim.codecs``) writes, so a client that
    converts by it (GStreamer does) gets the emulator's picture: YUV is BT.601 limited range, and GREY, a
    colour stream's luma or a mono sensor's samples, is full range (V4L2's default for a Y'CbCr format is
    limited)."""
    pf = device_format(fourcc)
    space = raw.Colorspace.JPEG if pf.compressed else raw.Colorspace.RAW if pf.raw else \
        raw.Colorspace.SRGB
    enc, quant = raw.YcbcrEnc.DEFAULT, raw.Quantization.DEFAULT
    if fourcc == "GREY":
        quant = raw.Quantization.FULL_RANGE
    elif pf.layout is not None and pf.layout.packing in YUV_PACKINGS:
        enc, quant = raw.YcbcrEnc.BT601, raw.Quantization.LIM_RANGE
    return raw.PixFormat(width=width, height=height, pixelformat=fourcc, field=raw.Field.NONE,
                         bytesperline=pf.bytesperline(width), sizeimage=pf.sizeimage(width, height), colorspace=space,
                         ycbcr_enc=enc, quantization=quant)


# ------------------------------------------------------------------------------------------------ handlers
def _querycap(d: EmuDriver, _arg: Any) -> raw.Capability:
    caps = raw.Cap.VIDEO_CAPTURE | raw.Cap.STREAMING | raw.Cap.EXT_PIX_FORMAT
    every = caps | (raw.Cap.META_CAPTURE if d.meta is not None else 0)  # the device's nodes together
    return raw.Capability("rollcam", f"rollcam {d.camera.sensor.name} emulator", "platform:rollcam-emu",
                          0x00060800, int(every | raw.Cap.DEVICE_CAPS), int(caps))


def _enum_fmt(d: EmuDriver, arg: raw.FmtDesc) -> raw.FmtDesc:
    formats = [device_format(f) for f in d.camera.formats]
    if not 0 <= arg.index < len(formats):
        raise V4L2Error(errno.EINVAL, f"format index {arg.index} out of range")
    pf = formats[arg.index]
    return raw.FmtDesc(arg.index, raw.BufType.VIDEO_CAPTURE, 1 if pf.compressed else 0, pf.description, pf.fourcc)


def _try_fmt(d: EmuDriver, arg: raw.PixFormat) -> raw.PixFormat:
    """TRY_FMT: the nearest offered size (as v4l2_find_nearest_size: the modes, and a scaled size the camera was
    made with) and a supported format (else the first); a raw
    Bayer fourcc comes back in the order the current flips give, as Linux sensor drivers answer."""
    sizes = d.sizes
    w, h = min(sizes, key=lambda s: abs(s[0] - arg.width) + abs(s[1] - arg.height))
    try:
        fourcc = d.camera.resolve_format(arg.pixelformat)
    except ConfigError:
        fourcc = d.camera.formats[0]
    return _pix_format(w, h, fourcc)


def _s_fmt(d: EmuDriver, arg: raw.PixFormat) -> raw.PixFormat:
    fmt = _try_fmt(d, arg)
    if d.queue.busy:
        raise V4L2Error(errno.EBUSY, "S_FMT while buffers are allocated (REQBUFS 0 first)")
    d.camera.set_size(fmt.width, fmt.height)
    d.camera.set_format(fmt.pixelformat)
    return d.fmt


def _enum_framesizes(d: EmuDriver, arg: raw.FrmSize) -> raw.FrmSize:
    sizes = d.sizes
    if arg.pixel_format not in d.camera.formats or not 0 <= arg.index < len(sizes):
        raise V4L2Error(errno.EINVAL, f"no frame size {arg.index} for format {arg.pixel_format!r}")
    return raw.FrmSize(arg.index, arg.pixel_format, raw.FrmSizeType.DISCRETE, *sizes[arg.index])


def _enum_frameintervals(d: EmuDriver, arg: raw.FrmIval) -> raw.FrmIval:
    if (arg.index != 0 or (arg.width, arg.height) not in d.sizes
            or arg.pixel_format not in d.camera.formats):
        raise V4L2Error(errno.EINVAL, f"no frame interval {arg.index} for {arg.pixel_format!r} "
                                      f"{arg.width}x{arg.height}")
    ival = default_interval(d.camera.spec, arg.width, arg.height)
    return raw.FrmIval(0, arg.pixel_format, arg.width, arg.height, raw.FrmSizeType.DISCRETE, ival.numerator,
                       ival.denominator)


def _g_parm(d: EmuDriver, _arg: Any) -> raw.StreamParm:
    t = d.camera.spec.settings.timing
    ival = Fraction(t.frame_period_pck, t.pixel_rate_hz)
    return raw.stream_parm(ival.numerator, ival.denominator)


def _s_parm(d: EmuDriver, arg: raw.StreamParm) -> raw.StreamParm:
    """S_PARM: the frame interval becomes the nearest frame length (vertical blanking) the mode allows."""
    t = arg.parm.capture.timeperframe
    if t.numerator <= 0 or t.denominator <= 0:
        return _g_parm(d, None)  # the kernel treats a zero fraction as "keep the current interval"
    d.camera.set_frame_interval_ns(round(Fraction(t.numerator, t.denominator) * 1_000_000_000))
    return _g_parm(d, None)


def _control_name(cid: int) -> str:
    try:
        return CID_TO_CONTROL[raw.CID(cid)]
    except ValueError:
        raise V4L2Error(errno.EINVAL, f"no control with id {cid:#x}") from None


def _queryctrl(d: EmuDriver, arg: raw.QueryCtrl) -> raw.QueryCtrl:
    name = _control_name(arg.id)
    info = d.camera.controls()[name]
    flags = raw.CtrlFlag.READ_ONLY if info["read_only"] else 0
    if name in ("hflip", "vflip") and d.camera.streaming:
        flags |= raw.CtrlFlag.GRABBED
    # default_value is the power-on value (the current one is G_CTRL's), as the preload node's QUERY_EXT_CTRL
    default = CONTROLS[name].get(d.camera.state) if name in ("hblank", "pixel_rate") else \
        d.ctrl_defaults.get(name, info["value"])
    return raw.QueryCtrl(arg.id, _CTRL_TYPES[info["kind"]], CTRL_NAMES[name], info["min"], info["max"], 1,
                         default, int(flags))


def _querymenu(d: EmuDriver, arg: raw.QueryMenu) -> raw.QueryMenu:
    info = d.camera.controls()[_control_name(arg.id)]
    if not info["menu"] or not 0 <= arg.index < len(info["menu"]):
        raise V4L2Error(errno.EINVAL, f"no menu item {arg.index} for control {arg.id:#x}")
    return raw.QueryMenu(arg.id, arg.index, info["menu"][arg.index])


def _g_ctrl(d: EmuDriver, arg: raw.Control) -> raw.Control:
    return raw.Control(arg.id, d.camera.get_control(_control_name(arg.id)))


def _s_ctrl(d: EmuDriver, arg: raw.Control) -> raw.Control:
    name = _control_name(arg.id)
    if CONTROLS[name].set is None:
        raise V4L2Error(errno.EACCES, f"control {name!r} is read-only")
    return raw.Control(arg.id, d.camera.set_control(name, int(arg.value)))


def _reqbufs(d: EmuDriver, arg: raw.RequestBuffers) -> raw.RequestBuffers:
    count = d.queue.request(arg.count, arg.memory, d.fmt.sizeimage)
    return raw.RequestBuffers(count, arg.type, arg.memory)


def _querybuf(d: EmuDriver, arg: raw.Buffer) -> BufferState:
    return d.queue.query(arg.index)


def _qbuf(d: EmuDriver, arg: raw.Buffer) -> BufferState:
    d.queue.queue(arg.index)
    return d.queue.query(arg.index)


def _dqbuf(d: EmuDriver, arg: dict[str, Any] | None) -> Slot:
    opts = arg or {}
    block, timeout_s = opts.get("block", True), opts.get("timeout_s")
    if d.pump is not None:
        try:
            d.pump.check()
        except DeviceError as exc:
            raise V4L2Error(errno.EIO, f"the frame pump stopped: {exc.__cause__!r}") from exc
    # As fast as possible: frames are made on demand, while a buffer is queued and none is done (injected
    # drops hand their buffer back, so this may take several frames).
    while not d.realtime and d.queue.streaming and not d.queue.done and d.queue.queued:
        if not d.produce_now():
            break
    return d.queue.dequeue(block, timeout_s)


def _streamon(d: EmuDriver, _arg: Any) -> None:
    if d.queue.streaming:
        return
    small = [s.info.length for s in d.queue.slots if s.info.length < d.fmt.sizeimage]
    if small:  # the format grew after REQBUFS (over another interface): vb2 refuses too-small buffers
        raise V4L2Error(errno.EINVAL, f"buffers of {small[0]} bytes cannot hold {d.fmt.pixelformat!r} frames of "
                                      f"{d.fmt.sizeimage} bytes; REQBUFS again")
    d.queue.start()
    d.seq0 = d.camera.next_seq  # V4L2 sequence numbers count from 0 at each STREAMON
    d.ts0 = None
    d.camera.stream_on()
    if d.realtime:
        d.pump = FramePump(d.camera, bands=d.bands, name="rollcam-v4l2", rt_priority=d.rt_priority)
        d.pump.add_sink(d)
        d.pump.start()


def _streamoff(d: EmuDriver, _arg: Any) -> None:
    try:
        d._stop_pump()
    finally:
        d.camera.stream_off()
        d.queue.stop()
        d._filling = None


_HANDLERS: dict[raw.Ioctl, Callable[[EmuDriver, Any], Any]] = {
    raw.Ioctl.QUERYCAP: _querycap, raw.Ioctl.ENUM_FMT: _enum_fmt, raw.Ioctl.G_FMT: lambda d, _a: d.fmt,
    raw.Ioctl.S_FMT: _s_fmt, raw.Ioctl.TRY_FMT: _try_fmt, raw.Ioctl.ENUM_FRAMESIZES: _enum_framesizes,
    raw.Ioctl.ENUM_FRAMEINTERVALS: _enum_frameintervals, raw.Ioctl.G_PARM: _g_parm, raw.Ioctl.S_PARM: _s_parm,
    raw.Ioctl.QUERYCTRL: _queryctrl, raw.Ioctl.QUERYMENU: _querymenu, raw.Ioctl.G_CTRL: _g_ctrl,
    raw.Ioctl.S_CTRL: _s_ctrl, raw.Ioctl.REQBUFS: _reqbufs, raw.Ioctl.QUERYBUF: _querybuf, raw.Ioctl.QBUF: _qbuf,
    raw.Ioctl.DQBUF: _dqbuf, raw.Ioctl.STREAMON: _streamon, raw.Ioctl.STREAMOFF: _streamoff,
    **ctrls.HANDLERS,
}
"""VIDIOC request -> handler(driver, arg)."""
