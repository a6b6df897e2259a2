"""V4L2 kernel constants and structures (videodev2.h, v4l2-controls.h): the one home of both, as linuxpy's raw.

The numbers are the kernel's, so code written against a real ``/dev/videoN`` reads the same here. Each structure
is declared once, as a ctypes structure in the kernel's binary layout (LP64 Linux: x86-64 and arm64 share it), and
is at once the value the in-process driver speaks and the bytes a program hands ``ioctl``: a text field reads and
takes a ``str``, a fourcc field its four characters, and the constructor takes fields in order or by name.
"""

from __future__ import annotations

import ctypes as C
import enum
from typing import Any, ClassVar


def fourcc_code(text: str) -> int:
    """``v4l2_fourcc(a, b, c, d)``: four ASCII characters as a little-endian u32."""
    if len(text) != 4:
        raise ValueError(f"a fourcc has 4 characters, got {text!r}")
    return int.from_bytes(text.encode("ascii"), "little")


def fourcc_text(code: int) -> str:
    """The four characters of a fourcc code."""
    return int(code).to_bytes(4, "little").decode("ascii", "replace")


class Cap(enum.IntFlag):
    """``V4L2_CAP_*`` device capabilities."""

    VIDEO_CAPTURE = 0x00000001
    META_CAPTURE = 0x00800000
    TIMEPERFRAME = 0x00001000  # v4l2_captureparm.capability
    EXT_PIX_FORMAT = 0x00200000
    READWRITE = 0x01000000
    STREAMING = 0x04000000
    DEVICE_CAPS = 0x80000000


class BufType(enum.IntEnum):
    """``enum v4l2_buf_type`` (capture only here)."""

    VIDEO_CAPTURE = 1
    META_CAPTURE = 13


class Memory(enum.IntEnum):
    """``enum v4l2_memory``."""

    MMAP = 1
    USERPTR = 2
    OVERLAY = 3
    DMABUF = 4


class Field(enum.IntEnum):
    """``enum v4l2_field`` (progressive only)."""

    ANY = 0
    NONE = 1


class BufFlag(enum.IntFlag):
    """``V4L2_BUF_FLAG_*``."""

    MAPPED = 0x00000001
    QUEUED = 0x00000002
    DONE = 0x00000004
    KEYFRAME = 0x00000008
    ERROR = 0x00000040
    TIMESTAMP_MONOTONIC = 0x00002000
    TSTAMP_SRC_SOE = 0x00010000


class Colorspace(enum.IntEnum):
    """``enum v4l2_colorspace`` (the three used here)."""

    JPEG = 7
    SRGB = 8
    RAW = 11


class YcbcrEnc(enum.IntEnum):
    """``enum v4l2_ycbcr_encoding`` (the one used here)."""

    DEFAULT = 0
    BT601 = 1


class Quantization(enum.IntEnum):
    """``enum v4l2_quantization``."""

    DEFAULT = 0
    FULL_RANGE = 1
    LIM_RANGE = 2


class CtrlType(enum.IntEnum):
    """``enum v4l2_ctrl_type``."""

    INTEGER = 1
    BOOLEAN = 2
    MENU = 3
    INTEGER64 = 5
    CTRL_CLASS = 6


class CtrlFlag(enum.IntFlag):
    """``V4L2_CTRL_FLAG_*``."""

    GRABBED = 0x0002
    READ_ONLY = 0x0004
    UPDATE = 0x0008
    INACTIVE = 0x0010
    WRITE_ONLY = 0x0040
    VOLATILE = 0x0080
    NEXT_CTRL = 0x80000000
    NEXT_COMPOUND = 0x40000000


_USER = 0x00980900
_CAMERA = 0x009A0900
_IMAGE_SOURCE = 0x009E0900
_IMAGE_PROC = 0x009F0900


class CID(enum.IntEnum):
    """``V4L2_CID_*`` of the sensor controls (user, image-source and image-process classes), the class
    controls, and rollcam's two read-only controls (``ROLLCAM_*``, in the camera class's driver-private range):
    the line time in ns (INTEGER64; 0 for a global shutter) and the readout direction (a menu)."""

    USER_CLASS = _USER - 0x900 + 1
    IMAGE_SOURCE_CLASS = _IMAGE_SOURCE - 0x900 + 1
    IMAGE_PROC_CLASS = _IMAGE_PROC - 0x900 + 1
    EXPOSURE = _USER + 17
    HFLIP = _USER + 20
    VFLIP = _USER + 21
    VBLANK = _IMAGE_SOURCE + 1
    HBLANK = _IMAGE_SOURCE + 2
    ANALOGUE_GAIN = _IMAGE_SOURCE + 3
    PIXEL_RATE = _IMAGE_PROC + 2
    TEST_PATTERN = _IMAGE_PROC + 3
    DIGITAL_GAIN = _IMAGE_PROC + 5
    CAMERA_CLASS = _CAMERA - 0x900 + 1
    EXPOSURE_ABSOLUTE = _CAMERA + 2
    ROLLCAM_LINE_TIME = _CAMERA + 0x1FF0
    ROLLCAM_READOUT = _CAMERA + 0x1FF1


class FrmSizeType(enum.IntEnum):
    """``enum v4l2_frmsizetypes``."""

    DISCRETE = 1


class Ioctl(str, enum.Enum):
    """The requests the emulated driver answers (``VIDIOC_*``)."""

    QUERYCAP = "VIDIOC_QUERYCAP"
    ENUM_FMT = "VIDIOC_ENUM_FMT"
    G_FMT = "VIDIOC_G_FMT"
    S_FMT = "VIDIOC_S_FMT"
    TRY_FMT = "VIDIOC_TRY_FMT"
    ENUM_FRAMESIZES = "VIDIOC_ENUM_FRAMESIZES"
    ENUM_FRAMEINTERVALS = "VIDIOC_ENUM_FRAMEINTERVALS"
    G_PARM = "VIDIOC_G_PARM"
    S_PARM = "VIDIOC_S_PARM"
    QUERYCTRL = "VIDIOC_QUERYCTRL"
    QUERYMENU = "VIDIOC_QUERYMENU"
    G_CTRL = "VIDIOC_G_CTRL"
    S_CTRL = "VIDIOC_S_CTRL"
    REQBUFS = "VIDIOC_REQBUFS"
    QUERYBUF = "VIDIOC_QUERYBUF"
    QBUF = "VIDIOC_QBUF"
    DQBUF = "VIDIOC_DQBUF"
    STREAMON = "VIDIOC_STREAMON"
    STREAMOFF = "VIDIOC_STREAMOFF"
    QUERY_EXT_CTRL = "VIDIOC_QUERY_EXT_CTRL"
    G_EXT_CTRLS = "VIDIOC_G_EXT_CTRLS"
    S_EXT_CTRLS = "VIDIOC_S_EXT_CTRLS"
    TRY_EXT_CTRLS = "VIDIOC_TRY_EXT_CTRLS"
    ENUMINPUT = "VIDIOC_ENUMINPUT"
    G_INPUT = "VIDIOC_G_INPUT"
    S_INPUT = "VIDIOC_S_INPUT"


class CtrlWhich(enum.IntEnum):
    """``v4l2_ext_controls.which``: current or default values (a control class value means current)."""

    CUR_VAL = 0
    DEF_VAL = 0x0F000000


INPUT_TYPE_CAMERA = 2
"""``V4L2_INPUT_TYPE_CAMERA``."""

VIDEO_MAX_FRAME = 32
"""Most buffers a queue holds (videodev2.h)."""


# ------------------------------------------------------------------------------------------------ structures
u8, u32, s32, s64, u64 = C.c_uint8, C.c_uint32, C.c_int32, C.c_int64, C.c_uint64


def cstr(text: str, size: int) -> bytes:
    """A NUL-terminated field of ``size`` bytes (truncated as the kernel's strscpy does)."""
    return text.encode("utf-8")[: size - 1].ljust(size, b"\0")


class View:
    """A field as Python code reads it, over the bytes the kernel reads: ``text(n)``/``fourcc()`` in ``_fields_``."""

    def __init__(self, ctype: Any) -> None:
        self.ctype = ctype
        self.field: Any = None  # the ctypes field it wraps, bound when the structure is made

    def __get__(self, obj: Any, owner: Any = None) -> Any:
        return self if obj is None else self.decode(self.field.__get__(obj, owner))

    def __set__(self, obj: Any, value: Any) -> None:
        self.encode(obj, value)

    def decode(self, stored: Any) -> Any:
        """The Python value of the stored field."""
        raise NotImplementedError

    def encode(self, obj: Any, value: Any) -> None:
        """Store ``value`` in ``obj``'s field."""
        raise NotImplementedError


class _Text(View):
    def decode(self, stored: Any) -> str:
        return bytes(stored).split(b"\0", 1)[0].decode("utf-8", "replace")

    def encode(self, obj: Any, value: Any) -> None:
        if not isinstance(value, str):
            raise TypeError(f"a text field of {type(obj).__name__} takes a str, got {value!r}")
        array = self.field.__get__(obj, type(obj))
        data = cstr(value, len(array))
        C.memmove(array, data, len(data))


class _FourCC(View):
    def decode(self, stored: Any) -> str:
        return fourcc_text(stored)

    def encode(self, obj: Any, value: Any) -> None:
        self.field.__set__(obj, fourcc_code(value) if isinstance(value, str) else int(value))


def text(size: int) -> View:
    """A NUL-terminated ``u8[size]`` field read and written as ``str``."""
    return _Text(u8 * size)


def fourcc() -> View:
    """A ``u32`` fourcc field read as its four characters (written as them or as the number)."""
    return _FourCC(u32)


class _StructType(type(C.Structure)):  # type: ignore[misc]
    """Lays out ``_fields_`` with each View's ctypes type, then puts the View over its field."""

    def __new__(mcs, name: str, bases: tuple[type, ...], ns: dict[str, Any]) -> Any:
        views = {n: t for n, t, *_ in ns.get("_fields_", ()) if isinstance(t, View)}
        if views:
            ns["_fields_"] = [(n, t.ctype, *rest) if isinstance(t, View) else (n, t, *rest)
                              for n, t, *rest in ns["_fields_"]]
        ns["_views_"] = views
        ns["_names_"] = frozenset(n for n, *_ in ns.get("_fields_", ()))
        return super().__new__(mcs, name, bases, ns)

    def __init__(cls, name: str, bases: tuple[type, ...], ns: dict[str, Any]) -> None:
        super().__init__(name, bases, ns)
        for field_name, view in cls._views_.items():
            view.field = cls.__dict__[field_name]
            setattr(cls, field_name, view)


class Struct(C.Structure, metaclass=_StructType):
    """A kernel structure: its bytes are the kernel's; equal when its bytes are; a readable repr."""

    _views_: ClassVar[dict[str, View]] = {}
    _names_: ClassVar[frozenset[str]] = frozenset()

    def __init__(self, *args: Any, **fields: Any) -> None:
        if len(args) > len(self._fields_):
            raise TypeError(f"{type(self).__name__} takes at most {len(self._fields_)} fields, got {len(args)}")
        if fields and not fields.keys() <= self._names_:
            raise TypeError(f"{type(self).__name__} has no field {sorted(fields.keys() - self._names_)[0]!r}")
        super().__init__(*args, **fields)  # ctypes sets each through its attribute: a View's encodes

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and bytes(self) == bytes(other)  # type: ignore[call-overload]

    __hash__ = None  # type: ignore[assignment]  # mutable, as the dataclasses it replaces

    def __repr__(self) -> str:
        shown = (name for name, *_ in self._fields_ if not name.startswith(("_", "reserved")))
        return f"{type(self).__name__}({', '.join(f'{name}={getattr(self, name)!r}' for name in shown)})"


class Capability(Struct):
    """``struct v4l2_capability``."""

    _fields_ = [("driver", text(16)), ("card", text(32)), ("bus_info", text(32)), ("version", u32),
                ("capabilities", u32), ("device_caps", u32), ("reserved", u32 * 3)]


class FmtDesc(Struct):
    """``struct v4l2_fmtdesc``."""

    _fields_ = [("index", u32), ("type", u32), ("flags", u32), ("description", text(32)), ("pixelformat", fourcc()),
                ("mbus_code", u32), ("reserved", u32 * 3)]


class PixFormat(Struct):
    """``struct v4l2_pix_format``."""

    _fields_ = [("width", u32), ("height", u32), ("pixelformat", fourcc()), ("field", u32), ("bytesperline", u32),
                ("sizeimage", u32), ("colorspace", u32), ("priv", u32), ("flags", u32), ("ycbcr_enc", u32),
                ("quantization", u32), ("xfer_func", u32)]


class MetaFormat(Struct):
    """``struct v4l2_meta_format``."""

    _fields_ = [("dataformat", fourcc()), ("buffersize", u32)]


class FormatUnion(C.Union):
    """``v4l2_format.fmt``."""

    _fields_ = [("pix", PixFormat), ("meta", MetaFormat), ("raw_data", u8 * 200), ("_align", C.c_void_p)]


class Format(Struct):
    """``struct v4l2_format``."""

    _fields_ = [("type", u32), ("fmt", FormatUnion)]


class RequestBuffers(Struct):
    """``struct v4l2_requestbuffers``."""

    _fields_ = [("count", u32), ("type", u32), ("memory", u32), ("capabilities", u32), ("flags", u8),
                ("reserved", u8 * 3)]


class TimeVal(Struct):
    """``struct timeval``."""

    _fields_ = [("tv_sec", C.c_long), ("tv_usec", C.c_long)]


class TimeCode(Struct):
    """``struct v4l2_timecode``."""

    _fields_ = [("type", u32), ("flags", u32), ("frames", u8), ("seconds", u8), ("minutes", u8), ("hours", u8),
                ("userbits", u8 * 4)]


class BufferM(C.Union):
    """``v4l2_buffer.m``."""

    _fields_ = [("offset", u32), ("userptr", C.c_ulong), ("planes", C.c_void_p), ("fd", s32)]


class Buffer(Struct):
    """``struct v4l2_buffer``; ``timestamp_ns`` reads and sets the ``timeval`` in integer ns (to the us)."""

    _fields_ = [("index", u32), ("type", u32), ("bytesused", u32), ("flags", u32), ("field", u32),
                ("timestamp", TimeVal), ("timecode", TimeCode), ("sequence", u32), ("memory", u32),
                ("m", BufferM), ("length", u32), ("reserved2", u32), ("request_fd", s32)]

    @property
    def timestamp_ns(self) -> int:
        """The timestamp (CLOCK_MONOTONIC) in ns."""
        return self.timestamp.tv_sec * 1_000_000_000 + self.timestamp.tv_usec * 1000

    @timestamp_ns.setter
    def timestamp_ns(self, ns: int) -> None:
        self.timestamp.tv_sec, self.timestamp.tv_usec = divmod(ns // 1000, 1_000_000)


class ExportBuffer(Struct):
    """``struct v4l2_exportbuffer``."""

    _fields_ = [("type", u32), ("index", u32), ("plane", u32), ("flags", u32), ("fd", s32), ("reserved", u32 * 11)]


class Fract(Struct):
    """``struct v4l2_fract``."""

    _fields_ = [("numerator", u32), ("denominator", u32)]


class CaptureParm(Struct):
    """``struct v4l2_captureparm``."""

    _fields_ = [("capability", u32), ("capturemode", u32), ("timeperframe", Fract), ("extendedmode", u32),
                ("readbuffers", u32), ("reserved", u32 * 4)]


class ParmUnion(C.Union):
    """``v4l2_streamparm.parm``."""

    _fields_ = [("capture", CaptureParm), ("raw_data", u8 * 200)]


class StreamParm(Struct):
    """``struct v4l2_streamparm``."""

    _fields_ = [("type", u32), ("parm", ParmUnion)]


def stream_parm(numerator: int, denominator: int) -> StreamParm:
    """Capture parameters (G/S_PARM) with time per frame ``numerator/denominator`` seconds."""
    capture = CaptureParm(capability=Cap.TIMEPERFRAME, timeperframe=Fract(numerator, denominator))
    return StreamParm(BufType.VIDEO_CAPTURE, ParmUnion(capture=capture))


class FrmSizeEnum(Struct):
    """``struct v4l2_frmsizeenum`` (discrete sizes: ``width``, ``height``; the stepwise rest unused)."""

    _fields_ = [("index", u32), ("pixel_format", fourcc()), ("type", u32), ("width", u32), ("height", u32),
                ("_stepwise", u32 * 4), ("reserved", u32 * 2)]


class FrmIvalEnum(Struct):
    """``struct v4l2_frmivalenum`` (discrete intervals: ``numerator``/``denominator`` seconds)."""

    _fields_ = [("index", u32), ("pixel_format", fourcc()), ("width", u32), ("height", u32), ("type", u32),
                ("numerator", u32), ("denominator", u32), ("_stepwise", u32 * 4), ("reserved", u32 * 2)]


FrmSize, FrmIval = FrmSizeEnum, FrmIvalEnum  # the names the in-process functions use


class Input(Struct):
    """``struct v4l2_input``."""

    _fields_ = [("index", u32), ("name", text(32)), ("type", u32), ("audioset", u32), ("tuner", u32),
                ("std", u64), ("status", u32), ("capabilities", u32), ("reserved", u32 * 3)]


class QueryCtrl(Struct):
    """``struct v4l2_queryctrl``."""

    _fields_ = [("id", u32), ("type", u32), ("name", text(32)), ("minimum", s32), ("maximum", s32), ("step", s32),
                ("default_value", s32), ("flags", u32), ("reserved", u32 * 2)]


class QueryExtCtrl(Struct):
    """``struct v4l2_query_ext_ctrl`` (``id`` may carry ``CtrlFlag.NEXT_CTRL``)."""

    _fields_ = [("id", u32), ("type", u32), ("name", text(32)), ("minimum", s64), ("maximum", s64),
                ("step", u64), ("default_value", s64), ("flags", u32), ("elem_size", u32), ("elems", u32),
                ("nr_of_dims", u32), ("dims", u32 * 4), ("reserved", u32 * 32)]


class QueryMenu(Struct):
    """``struct v4l2_querymenu``."""

    _pack_ = 1
    _fields_ = [("id", u32), ("index", u32), ("name", text(32)), ("reserved", u32)]


class Control(Struct):
    """``struct v4l2_control``."""

    _fields_ = [("id", u32), ("value", s32)]


class ExtControl(Struct):
    """``struct v4l2_ext_control`` (its value union as ``value64``; a 32-bit control's value is its low half)."""

    _pack_ = 1
    _fields_ = [("id", u32), ("size", u32), ("reserved2", u32), ("value64", s64)]


class ExtControls(Struct):
    """``struct v4l2_ext_controls``; ``controls`` is the address of ``count`` ExtControl (``ext_controls``)."""

    _fields_ = [("which", u32), ("count", u32), ("error_idx", u32), ("request_fd", s32), ("reserved", u32),
                ("controls", C.c_void_p)]


def ext_controls(arg: ExtControls) -> C.Array:
    """The ``count`` ExtControl that ``arg.controls`` points at (in this process's memory)."""
    return (ExtControl * arg.count).from_address(arg.controls) if arg.count else (ExtControl * 0)()


class EventSubscription(Struct):
    """``struct v4l2_event_subscription``."""

    _fields_ = [("type", u32), ("id", u32), ("flags", u32), ("reserved", u32 * 5)]


class EventCtrl(Struct):
    """``struct v4l2_event_ctrl``."""

    _fields_ = [("changes", u32), ("type", u32), ("value64", s64), ("flags", u32), ("minimum", s32),
                ("maximum", s32), ("step", s32), ("default_value", s32)]


class EventUnion(C.Union):
    """``v4l2_event.u``."""

    _fields_ = [("ctrl", EventCtrl), ("data", u8 * 64), ("_align", u64)]


class TimeSpec(Struct):
    """``struct timespec``."""

    _fields_ = [("tv_sec", C.c_long), ("tv_nsec", C.c_long)]


class Event(Struct):
    """``struct v4l2_event``."""

    _fields_ = [("type", u32), ("u", EventUnion), ("pending", u32), ("sequence", u32), ("timestamp", TimeSpec),
                ("id", u32), ("reserved", u32 * 8)]


class Selection(Struct):
    """``struct v4l2_selection``."""

    _fields_ = [("type", u32), ("target", u32), ("flags", u32), ("left", s32), ("top", s32), ("width", u32),
                ("height", u32), ("reserved", u32 * 9)]
