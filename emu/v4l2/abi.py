"""The kernel's binary layout of the V4L2 structures and the ``VIDIOC_*`` request numbers (LP64 Linux).

What a program hands ``ioctl(fd, VIDIOC_..., &arg)`` arrives at the device node (``rollcam.emu.v4l2.node``) as
the bytes of ``arg``; these ctypes structures read and write them. Layouts are videodev2.h's on 64-bit Linux
(x86-64 and arm64 share them); ``raw`` keeps the Python-side values.
"""

from __future__ import annotations

import ctypes as C

u8, u32, s32, s64, u64 = C.c_uint8, C.c_uint32, C.c_int32, C.c_int64, C.c_uint64


class Struct(C.Structure):
    """A kernel structure with a readable repr."""

    def __repr__(self) -> str:
        fields = ", ".join(f"{name}={getattr(self, name)!r}" for name, *_ in self._fields_ if name != "reserved")
        return f"{type(self).__name__}({fields})"


class Capability(Struct):
    _fields_ = [("driver", u8 * 16), ("card", u8 * 32), ("bus_info", u8 * 32), ("version", u32),
                ("capabilities", u32), ("device_caps", u32), ("reserved", u32 * 3)]


class FmtDesc(Struct):
    _fields_ = [("index", u32), ("type", u32), ("flags", u32), ("description", u8 * 32), ("pixelformat", u32),
                ("mbus_code", u32), ("reserved", u32 * 3)]


class PixFormat(Struct):
    _fields_ = [("width", u32), ("height", u32), ("pixelformat", u32), ("field", u32), ("bytesperline", u32),
                ("sizeimage", u32), ("colorspace", u32), ("priv", u32), ("flags", u32), ("ycbcr_enc", u32),
                ("quantization", u32), ("xfer_func", u32)]


class MetaFormat(Struct):
    _fields_ = [("dataformat", u32), ("buffersize", u32)]


class _FormatUnion(C.Union):
    _fields_ = [("pix", PixFormat), ("meta", MetaFormat), ("raw_data", u8 * 200), ("_align", C.c_void_p)]


class Format(Struct):
    _fields_ = [("type", u32), ("fmt", _FormatUnion)]


class RequestBuffers(Struct):
    _fields_ = [("count", u32), ("type", u32), ("memory", u32), ("capabilities", u32), ("flags", u8),
                ("reserved", u8 * 3)]


class TimeVal(Struct):
    _fields_ = [("tv_sec", C.c_long), ("tv_usec", C.c_long)]


class TimeCode(Struct):
    _fields_ = [("type", u32), ("flags", u32), ("frames", u8), ("seconds", u8), ("minutes", u8), ("hours", u8),
                ("userbits", u8 * 4)]


class _BufferM(C.Union):
    _fields_ = [("offset", u32), ("userptr", C.c_ulong), ("planes", C.c_void_p), ("fd", s32)]


class Buffer(Struct):
    _fields_ = [("index", u32), ("type", u32), ("bytesused", u32), ("flags", u32), ("field", u32),
                ("timestamp", TimeVal), ("timecode", TimeCode), ("sequence", u32), ("memory", u32),
                ("m", _BufferM), ("length", u32), ("reserved2", u32), ("request_fd", s32)]


class ExportBuffer(Struct):
    _fields_ = [("type", u32), ("index", u32), ("plane", u32), ("flags", u32), ("fd", s32), ("reserved", u32 * 11)]


class Fract(Struct):
    _fields_ = [("numerator", u32), ("denominator", u32)]


class CaptureParm(Struct):
    _fields_ = [("capability", u32), ("capturemode", u32), ("timeperframe", Fract), ("extendedmode", u32),
                ("readbuffers", u32), ("reserved", u32 * 4)]


class _ParmUnion(C.Union):
    _fields_ = [("capture", CaptureParm), ("raw_data", u8 * 200)]


class StreamParm(Struct):
    _fields_ = [("type", u32), ("parm", _ParmUnion)]


class FrmSizeEnum(Struct):
    _fields_ = [("index", u32), ("pixel_format", u32), ("type", u32), ("width", u32), ("height", u32),
                ("_stepwise", u32 * 4), ("reserved", u32 * 2)]


class FrmIvalEnum(Struct):
    _fields_ = [("index", u32), ("pixel_format", u32), ("width", u32), ("height", u32), ("type", u32),
                ("numerator", u32), ("denominator", u32), ("_stepwise", u32 * 4), ("reserved", u32 * 2)]


class Input(Struct):
    _fields_ = [("index", u32), ("name", u8 * 32), ("type", u32), ("audioset", u32), ("tuner", u32),
                ("std", u64), ("status", u32), ("capabilities", u32), ("reserved", u32 * 3)]


class QueryCtrl(Struct):
    _fields_ = [("id", u32), ("type", u32), ("name", u8 * 32), ("minimum", s32), ("maximum", s32), ("step", s32),
                ("default_value", s32), ("flags", u32), ("reserved", u32 * 2)]


class QueryExtCtrl(Struct):
    _fields_ = [("id", u32), ("type", u32), ("name", C.c_char * 32), ("minimum", s64), ("maximum", s64),
                ("step", u64), ("default_value", s64), ("flags", u32), ("elem_size", u32), ("elems", u32),
                ("nr_of_dims", u32), ("dims", u32 * 4), ("reserved", u32 * 32)]


class QueryMenu(Struct):
    _pack_ = 1
    _fields_ = [("id", u32), ("index", u32), ("name", u8 * 32), ("reserved", u32)]


class Control(Struct):
    _fields_ = [("id", u32), ("value", s32)]


class ExtControl(Struct):
    _pack_ = 1
    _fields_ = [("id", u32), ("size", u32), ("reserved2", u32), ("value64", s64)]


class ExtControls(Struct):
    _fields_ = [("which", u32), ("count", u32), ("error_idx", u32), ("request_fd", s32), ("reserved", u32),
                ("controls", C.c_void_p)]


class EventSubscription(Struct):
    _fields_ = [("type", u32), ("id", u32), ("flags", u32), ("reserved", u32 * 5)]


class EventCtrl(Struct):
    _fields_ = [("changes", u32), ("type", u32), ("value64", s64), ("flags", u32), ("minimum", s32),
                ("maximum", s32), ("step", s32), ("default_value", s32)]


class _EventUnion(C.Union):
    _fields_ = [("ctrl", EventCtrl), ("data", u8 * 64), ("_align", u64)]


class TimeSpec(Struct):
    _fields_ = [("tv_sec", C.c_long), ("tv_nsec", C.c_long)]


class Event(Struct):
    _fields_ = [("type", u32), ("u", _EventUnion), ("pending", u32), ("sequence", u32), ("timestamp", TimeSpec),
                ("id", u32), ("reserved", u32 * 8)]


class Selection(Struct):
    _fields_ = [("type", u32), ("target", u32), ("flags", u32), ("left", s32), ("top", s32), ("width", u32),
                ("height", u32), ("reserved", u32 * 9)]


# -------------------------------------------------------------------------------------------- request numbers
_IOC_WRITE, _IOC_READ = 1, 2


def _ioc(direction: int, nr: int, struct: type | None) -> int:
    size = 0 if struct is None else C.sizeof(struct)
    return (direction << 30) | (size << 16) | (ord("V") << 8) | nr


_R, _W, _RW = _IOC_READ, _IOC_WRITE, _IOC_READ | _IOC_WRITE

REQUESTS: dict[str, tuple[int, type | None]] = {
    "QUERYCAP": (_ioc(_R, 0, Capability), Capability),
    "ENUM_FMT": (_ioc(_RW, 2, FmtDesc), FmtDesc),
    "G_FMT": (_ioc(_RW, 4, Format), Format),
    "S_FMT": (_ioc(_RW, 5, Format), Format),
    "REQBUFS": (_ioc(_RW, 8, RequestBuffers), RequestBuffers),
    "QUERYBUF": (_ioc(_RW, 9, Buffer), Buffer),
    "QBUF": (_ioc(_RW, 15, Buffer), Buffer),
    "EXPBUF": (_ioc(_RW, 16, ExportBuffer), ExportBuffer),
    "DQBUF": (_ioc(_RW, 17, Buffer), Buffer),
    "STREAMON": (_ioc(_W, 18, C.c_int), C.c_int),
    "STREAMOFF": (_ioc(_W, 19, C.c_int), C.c_int),
    "G_PARM": (_ioc(_RW, 21, StreamParm), StreamParm),
    "S_PARM": (_ioc(_RW, 22, StreamParm), StreamParm),
    "G_STD": (_ioc(_R, 23, C.c_uint64), C.c_uint64),
    "S_STD": (_ioc(_W, 24, C.c_uint64), C.c_uint64),
    "ENUMINPUT": (_ioc(_RW, 26, Input), Input),
    "G_CTRL": (_ioc(_RW, 27, Control), Control),
    "S_CTRL": (_ioc(_RW, 28, Control), Control),
    "QUERYCTRL": (_ioc(_RW, 36, QueryCtrl), QueryCtrl),
    "QUERYMENU": (_ioc(_RW, 37, QueryMenu), QueryMenu),
    "G_INPUT": (_ioc(_R, 38, C.c_int), C.c_int),
    "S_INPUT": (_ioc(_RW, 39, C.c_int), C.c_int),
    "TRY_FMT": (_ioc(_RW, 64, Format), Format),
    "G_PRIORITY": (_ioc(_R, 67, C.c_uint32), C.c_uint32),
    "S_PRIORITY": (_ioc(_W, 68, C.c_uint32), C.c_uint32),
    "LOG_STATUS": (_ioc(0, 70, None), None),
    "G_EXT_CTRLS": (_ioc(_RW, 71, ExtControls), ExtControls),
    "S_EXT_CTRLS": (_ioc(_RW, 72, ExtControls), ExtControls),
    "TRY_EXT_CTRLS": (_ioc(_RW, 73, ExtControls), ExtControls),
    "ENUM_FRAMESIZES": (_ioc(_RW, 74, FrmSizeEnum), FrmSizeEnum),
    "ENUM_FRAMEINTERVALS": (_ioc(_RW, 75, FrmIvalEnum), FrmIvalEnum),
    "DQEVENT": (_ioc(_R, 89, Event), Event),
    "SUBSCRIBE_EVENT": (_ioc(_W, 90, EventSubscription), EventSubscription),
    "UNSUBSCRIBE_EVENT": (_ioc(_W, 91, EventSubscription), EventSubscription),
    "G_SELECTION": (_ioc(_RW, 94, Selection), Selection),
    "QUERY_EXT_CTRL": (_ioc(_RW, 103, QueryExtCtrl), QueryExtCtrl),
}
"""Request name -> (number, argument structure)."""

BY_NUMBER: dict[int, tuple[str, type | None]] = {num: (name, st) for name, (num, st) in REQUESTS.items()}
"""Request number -> (name, argument structure)."""


def cstr(text: str, size: int) -> bytes:
    """A NUL-terminated field of ``size`` bytes (truncated as the kernel's strscpy does)."""
    return text.encode("utf-8")[: size - 1].ljust(size, b"\0")


def set_str(field: C.Array, text: str) -> None:
    """Write ``text`` into a ``u8[N]`` field."""
    data = cstr(text, len(field))
    C.memmove(field, data, len(data))


def get_str(field: C.Array) -> str:
    """The text of a NUL-terminated ``u8[N]`` field."""
    return bytes(field).split(b"\0", 1)[0].decode("utf-8", "replace")
