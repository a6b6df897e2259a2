"""V4L2 kernel constants and structures (videodev2.h, v4l2-controls.h) as Python values and dataclasses.

The numbers are the kernel's, so code written against a real ``/dev/videoN`` reads the same here. Structures
keep the fields an application uses; times are integer ns rather than ``struct timeval``.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass


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


@dataclass
class Capability:
    """``struct v4l2_capability``."""

    driver: str = ""
    card: str = ""
    bus_info: str = ""
    version: int = 0
    capabilities: int = 0
    device_caps: int = 0


@dataclass
class PixFormat:
    """``struct v4l2_pix_format`` (``pixelformat`` as its four characters)."""

    width: int = 0
    height: int = 0
    pixelformat: str = ""
    field: int = Field.NONE
    bytesperline: int = 0
    sizeimage: int = 0
    colorspace: int = Colorspace.SRGB
    ycbcr_enc: int = YcbcrEnc.DEFAULT
    quantization: int = Quantization.DEFAULT


@dataclass
class FmtDesc:
    """``struct v4l2_fmtdesc``."""

    index: int
    type: int = BufType.VIDEO_CAPTURE
    flags: int = 0
    description: str = ""
    pixelformat: str = ""


@dataclass
class FrmSize:
    """``struct v4l2_frmsizeenum`` (discrete sizes)."""

    index: int
    pixel_format: str
    type: int = FrmSizeType.DISCRETE
    width: int = 0
    height: int = 0


@dataclass
class FrmIval:
    """``struct v4l2_frmivalenum`` (discrete intervals as a fraction of seconds)."""

    index: int
    pixel_format: str
    width: int
    height: int
    type: int = FrmSizeType.DISCRETE
    numerator: int = 0
    denominator: int = 0


@dataclass
class StreamParm:
    """``struct v4l2_streamparm`` for capture: time per frame as a fraction of seconds."""

    type: int = BufType.VIDEO_CAPTURE
    capability: int = Cap.TIMEPERFRAME
    numerator: int = 0
    denominator: int = 0


@dataclass
class QueryCtrl:
    """``struct v4l2_queryctrl``."""

    id: int
    type: int = 0
    name: str = ""
    minimum: int = 0
    maximum: int = 0
    step: int = 0
    default_value: int = 0
    flags: int = 0


@dataclass
class QueryMenu:
    """``struct v4l2_querymenu``."""

    id: int
    index: int
    name: str = ""


@dataclass
class Control:
    """``struct v4l2_control``."""

    id: int
    value: int = 0


@dataclass
class RequestBuffers:
    """``struct v4l2_requestbuffers``."""

    count: int
    type: int = BufType.VIDEO_CAPTURE
    memory: int = Memory.MMAP


@dataclass
class Buffer:
    """``struct v4l2_buffer``; ``timestamp_ns`` is CLOCK_MONOTONIC in ns (the kernel's timeval, unsplit)."""

    index: int
    type: int = BufType.VIDEO_CAPTURE
    bytesused: int = 0
    flags: int = 0
    field: int = Field.NONE
    timestamp_ns: int = 0
    sequence: int = 0
    memory: int = Memory.MMAP
    length: int = 0


@dataclass
class QueryExtCtrl(QueryCtrl):
    """``struct v4l2_query_ext_ctrl``: ``v4l2_queryctrl``'s fields and the element layout (``id`` may carry
    ``CtrlFlag.NEXT_CTRL``)."""

    elem_size: int = 4
    elems: int = 1


@dataclass
class ExtControls:
    """``struct v4l2_ext_controls`` with its array as ``[id, value]`` pairs; ``error_idx`` comes back set."""

    which: int
    controls: list[list[int]]
    error_idx: int = 0


@dataclass
class Input:
    """``struct v4l2_input``."""

    index: int
    name: str = ""
    type: int = INPUT_TYPE_CAMERA
