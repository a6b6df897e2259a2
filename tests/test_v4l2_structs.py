"""One V4L2 structure layer: each kernel structure is declared once (``raw``) and is both the value the in-process
driver speaks and the bytes a program's ioctl carries; the device node answers with it whole."""

from __future__ import annotations

import ctypes as C
import errno
import os

import pytest
from rollcam.emu.v4l2 import V4L2Error, abi, ioctls, raw
from rollcam.emu.v4l2 import functions as fn
from rollcam.emu.v4l2.driver import EmuDriver
from rollcam.emu.v4l2.node import DeviceNode
from rollcam.firmware.camera import FirmwareCamera


@pytest.fixture
def node():
    n = DeviceNode(EmuDriver(FirmwareCamera("imx219", scene={"scene": "flat"}, size=(640, 480)), realtime=False))
    yield n
    n.driver.close()


def ask(node: DeviceNode, f, name: str, arg: C.Structure, extra: bytes = b""):
    """One ioctl through the node as a program makes it: the argument's bytes in, the answer's bytes out."""
    number, struct = abi.REQUESTS[name]
    answer = ioctls.handle(node, f, number, bytes(arg) + extra)
    return struct.from_buffer_copy(answer.data[: C.sizeof(struct)]), answer.data[C.sizeof(struct):]


def test_every_request_structure_is_raws_one_class():
    for name, (_number, struct) in abi.REQUESTS.items():
        if struct is not None and issubclass(struct, C.Structure):
            assert getattr(raw, struct.__name__) is struct, name
            assert issubclass(struct, raw.Struct), name


def test_the_driver_answers_in_the_kernels_layout(node):
    fmt = fn.set_format(node.driver, 640, 480, "YUYV")
    assert type(fmt) is raw.PixFormat and fmt.pixelformat == "YUYV"
    data = bytes(fmt)
    assert len(data) == 48 and data[8:12] == b"YUYV"
    assert int.from_bytes(data[0:4], "little") == 640 and int.from_bytes(data[20:24], "little") == fmt.sizeimage
    cap = fn.querycap(node.driver)
    assert type(cap) is raw.Capability and bytes(cap)[:8] == b"rollcam\0"
    assert fn.get_frame_interval(node.driver)[1] > 0


def test_text_and_fourcc_fields_read_as_str():
    cap = raw.Capability(driver="d" * 40, card="caméra")
    assert cap.driver == "d" * 15 and bytes(cap)[:16] == b"d" * 15 + b"\0"  # truncated as strscpy does
    assert cap.card == "caméra" and bytes(cap)[16:24] == "caméra".encode() + b"\0"
    pix = raw.PixFormat(pixelformat="MJPG")
    assert pix.pixelformat == "MJPG" and bytes(pix)[8:12] == b"MJPG"
    pix.pixelformat = raw.fourcc_code("GREY")  # a number goes in as it is
    assert pix.pixelformat == "GREY"
    with pytest.raises(TypeError, match="Capability takes a str, got b'x'"):
        raw.Capability(card=b"x")
    with pytest.raises(ValueError, match="a fourcc has 4 characters"):
        raw.PixFormat(pixelformat="YUV")


def test_constructor_equality_and_repr():
    assert raw.Control(7, -2) == raw.Control(id=7, value=-2) != raw.Control(7, 3)
    assert raw.QueryMenu(1, 2, "a") != raw.Control(1, 2)
    with pytest.raises(TypeError, match="no field 'colour'"):
        raw.PixFormat(colour=1)
    with pytest.raises(TypeError, match="at most 2 fields"):
        raw.Control(1, 2, 3)
    text = repr(raw.FmtDesc(3, description="YUYV 4:2:2", pixelformat="YUYV"))
    assert "index=3" in text and "pixelformat='YUYV'" in text and "reserved" not in text
    assert raw.stream_parm(1, 30).parm.capture.timeperframe.denominator == 30


def test_node_answers_the_drivers_structure_whole(node):
    f = node.open(os.O_RDWR)
    cap, _ = ask(node, f, "QUERYCAP", raw.Capability())
    assert cap.bus_info == "platform:rollcam-emu-0" and cap.device_caps & raw.Cap.READWRITE
    garbage = raw.FrmSizeEnum(0, "YUYV")
    C.memset(C.addressof(garbage) + 12, 0xAB, C.sizeof(garbage) - 12)  # what a careless program leaves there
    size, _ = ask(node, f, "ENUM_FRAMESIZES", garbage)
    assert size.pixel_format == "YUYV" and size.type == raw.FrmSizeType.DISCRETE and size.width > 0
    assert bytes(size)[20:] == bytes(C.sizeof(size) - 20)  # the rest cleared, as Linux's ioctl core clears it
    fmt, _ = ask(node, f, "G_FMT", raw.Format(type=1))
    assert fmt.fmt.pix.pixelformat == node.driver.fmt.pixelformat and fmt.fmt.pix.priv == ioctls.PRIV_MAGIC


def test_extended_controls_through_the_node(node):
    f = node.open(os.O_RDWR)
    items = (raw.ExtControl * 2)(raw.ExtControl(id=raw.CID.EXPOSURE, value64=(0x5A5A << 32) | 100),
                                 raw.ExtControl(id=raw.CID.PIXEL_RATE, value64=0x5A5A << 32))
    arg = raw.ExtControls(which=0, count=2, controls=0x7F0000001000)  # the program's pointer, not ours
    out, extra = ask(node, f, "G_EXT_CTRLS", arg, bytes(items))
    back = (raw.ExtControl * 2).from_buffer_copy(extra)
    exposure = node.driver.camera.get_control("exposure")
    assert out.controls == 0x7F0000001000 and out.error_idx == 0
    assert back[0].value64 == (0x5A5A << 32) | exposure  # a 32-bit control: the low half only
    assert back[1].value64 == node.driver.camera.get_control("pixel_rate") > 0  # a 64-bit one: all of it
    items[1].id = 0x999
    with pytest.raises(V4L2Error) as info:
        ask(node, f, "TRY_EXT_CTRLS", arg, bytes(items))
    assert info.value.errno == errno.EINVAL
    assert raw.ExtControls.from_buffer_copy(info.value.data).error_idx == 1  # TRY names the failing control


def test_buffer_state_keeps_integer_ns_and_the_node_gives_the_kernels_timeval():
    ticks = iter(range(1_000_000_007, 10**12, 333_333_331))
    cam = FirmwareCamera("imx219", scene={"scene": "flat"}, size=(640, 480), clock=lambda: next(ticks))
    node = DeviceNode(EmuDriver(cam, realtime=False))
    f = node.open(os.O_RDWR)
    ask(node, f, "REQBUFS", raw.RequestBuffers(2, 1, raw.Memory.MMAP))
    for i in range(2):
        ask(node, f, "QBUF", raw.Buffer(i, 1, memory=raw.Memory.MMAP))
    ioctls.handle(node, f, abi.REQUESTS["STREAMON"][0], bytes(C.c_int(1)))
    buf, _ = ask(node, f, "DQBUF", raw.Buffer(type=1, memory=raw.Memory.MMAP))
    state = node.driver.queue.query(buf.index)
    assert state.timestamp_ns % 1000 != 0  # the queue keeps integer ns...
    assert buf.timestamp_ns == state.timestamp_ns // 1000 * 1000  # ...struct v4l2_buffer carries a timeval
    assert buf.flags & raw.BufFlag.TIMESTAMP_MONOTONIC and buf.m.offset == node.offset(buf.index)
    node.release(f)
    node.driver.close()
