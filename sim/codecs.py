"""The codec table: how every fourcc is encoded, decoded and previewed. rollcam converts pixels nowhere else.

``codec(fourcc)`` is the row of a fourcc of ``rollcam.sim.formats.FORMATS`` (whose layouts it uses) or of MJPG,
the one compressed format. Every row answers the same three calls:

- ``encode(image)``: the wire data a device sends. Picture formats (BGR3, RGB3, YUYV, UYVY, NV12, YU12, XR24)
  and MJPG take an 8-bit BGR image; raw ones take ADC samples ``uint16 (H, W)`` ``sample_bits`` wide (a
  narrower format keeps the high bits, as a sensor set to RAW8 does); MJPG gives a 1-D uint8 array, a baseline
  JPEG at ``JPEG_QUALITY`` unless told otherwise.
- ``decode(data, width, height)``: wire data (bytes, a flat buffer or the layout's array) -> the array it holds:
  BGR ``uint8 (H, W, 3)`` for pictures and MJPG, samples ``uint16 (H, W)`` at the format's own bit depth for
  raw formats (CSI-2 unpacked). A buffer of the wrong size or an undecodable JPEG is a ProtocolError.
- ``preview(data, width, height, levels)``: wire data -> the 8-bit BGR picture shown for it. Raw samples go
  through the preview ISP (``rollcam.sim.isp``): the sensor's black level (``Levels``, scaled to the format's
  bits) is subtracted, the format's full scale is white, then demosaic and sRGB gamma. Without levels the
  black level is taken as 0.

GREY is both a mono sensor's 8-bit samples and an ISP's luma: with the sensor's levels it is previewed as
samples, without them shown as the grey picture it is. ``preview_frame`` and ``transcode`` apply the table to
a ``Frame``; the transports (V4L2, UVC, HTTP) and the host's previews all go through them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError, ProtocolError
from rollcam.common.values import JPEG_QUALITY, jpeg_quality

from .formats import FORMATS, PixelFormat, pack_csi2, unpack_csi2
from .frame import Frame
from .isp import IspParams, preview


@dataclass(frozen=True)
class Levels:
    """What a raw preview takes from the sensor: its black level in DN of its ``bit_depth``-bit ADC."""

    black_level_dn: float
    bit_depth: int

    @classmethod
    def of_sensor(cls, sensor: Any) -> Levels:
        """The levels of a ``rollcam.sim.hwconfig.SensorConfig``."""
        return cls(float(sensor.noise.black_level_dn), int(sensor.bit_depth))

    @classmethod
    def of_frame(cls, frame: Frame) -> Levels | None:
        """The levels a raw frame of the sensor model records in its ``meta``; None when the frame does not
        carry that sensor's own samples (a picture, or GREY luma of a colour sensor)."""
        m = frame.meta
        layout = FORMATS.get(frame.format)
        if layout is None or not layout.is_raw or "black_level_dn" not in m or "bit_depth" not in m:
            return None
        if (layout.cfa == "mono") != (m.get("cfa", layout.cfa) == "mono"):
            return None
        return cls(float(m["black_level_dn"]), int(m["bit_depth"]))

    def isp(self, layout: PixelFormat) -> IspParams:
        """Preview ISP settings for samples of ``layout``: black scaled to its bits, its full scale white."""
        white = float((1 << layout.bits) - 1)
        black = self.black_level_dn / (1 << max(self.bit_depth - layout.bits, 0))
        return IspParams(black_level_dn=min(black, white - 1), white_level_dn=white)


def _cv2() -> Any:
    import cv2

    return cv2


def encode_image(image: np.ndarray, ext: str, params: tuple[int, ...] = (), error: type[Exception] = ConfigError,
                 what: str = "image") -> bytes:
    """``image`` as the bytes of an image file of type ``ext`` (``"png"``, ``"jpg"``...; OpenCV's encoder, with its
    ``params``): the one place a picture becomes a file's bytes (snapshots, contact sheets, masks, captures). A
    failed encode raises the caller's ``error`` naming ``what``."""
    cv2 = _cv2()
    ok, buf = cv2.imencode(f".{ext}", image, list(params))
    if not ok:
        raise error(f"could not encode {what} as {ext.upper()}")
    return buf.tobytes()


def _as_bgr(image: np.ndarray, fourcc: str) -> np.ndarray:
    """``image`` checked to be an 8-bit BGR picture, contiguous."""
    a = np.asarray(image)
    if a.ndim != 3 or a.shape[2] != 3 or a.dtype != np.uint8:
        raise ConfigError(f"{fourcc} encodes an 8-bit BGR image (H, W, 3), got shape {a.shape} {a.dtype}")
    return np.ascontiguousarray(a)


class Codec:
    """One fourcc's row: ``encode``, ``decode`` and ``preview`` (see the module docstring)."""

    raw = False
    """True for sensor samples (Bayer or mono), which previews pass through the preview ISP."""

    def __init__(self, fourcc: str, layout: PixelFormat | None) -> None:
        self.fourcc = fourcc
        self.layout = layout
        """The ``rollcam.sim.formats`` layout (shape, sizes); None for MJPG, whose frames vary in size."""

    def __repr__(self) -> str:
        return f"<codec {self.fourcc}>"

    @property
    def compressed(self) -> bool:
        """True for formats whose frames vary in size (MJPG)."""
        return self.layout is None

    def wire(self, data: bytes | np.ndarray, width: int, height: int) -> np.ndarray:
        """``data`` as the layout's array (shape and dtype); ProtocolError when its size does not fit."""
        f = self.layout
        assert f is not None
        shape = f.shape(width, height)
        a = np.frombuffer(data, np.uint8) if isinstance(data, (bytes, bytearray, memoryview)) else np.asarray(data)
        if a.shape == shape and a.dtype == f.dtype:
            return a
        flat = np.ascontiguousarray(a).reshape(-1).view(np.uint8)
        need = f.sizeimage(width, height)
        if flat.size != need:
            raise ProtocolError(f"{self.fourcc} {width}x{height} frame needs {need} bytes, got {flat.size}")
        return flat.view(f.dtype).reshape(shape)

    def encode(self, image: np.ndarray, *, sample_bits: int | None = None, quality: int = JPEG_QUALITY
               ) -> np.ndarray:
        """Wire data of ``image`` (BGR, or samples for raw formats)."""
        raise NotImplementedError

    def decode(self, data: bytes | np.ndarray, width: int, height: int) -> np.ndarray:
        """The array ``data`` holds (BGR, or samples for raw formats)."""
        raise NotImplementedError

    def preview(self, data: bytes | np.ndarray, width: int, height: int, levels: Levels | None = None
                ) -> np.ndarray:
        """The 8-bit BGR picture shown for ``data``; ``levels`` (raw formats) gives the black level."""
        return self.decode(data, width, height)


class _Picture(Codec):
    """A processed format: BGR to and from its layout."""

    def __init__(self, fourcc: str, layout: PixelFormat, to_wire: Callable[[np.ndarray], np.ndarray],
                 to_bgr: Callable[[np.ndarray], np.ndarray]) -> None:
        super().__init__(fourcc, layout)
        self._to_wire, self._to_bgr = to_wire, to_bgr

    def encode(self, image: np.ndarray, *, sample_bits: int | None = None, quality: int = JPEG_QUALITY
               ) -> np.ndarray:
        return self._to_wire(_as_bgr(image, self.fourcc))

    def decode(self, data: bytes | np.ndarray, width: int, height: int) -> np.ndarray:
        return self._to_bgr(self.wire(data, width, height))


class _Raw(Codec):
    """Sensor samples: Bayer or mono, unpacked (uint8 / uint16) or MIPI CSI-2 packed."""

    raw = True

    def encode(self, image: np.ndarray, *, sample_bits: int | None = None, quality: int = JPEG_QUALITY
               ) -> np.ndarray:
        f = self.layout
        assert f is not None
        bits = f.bits if sample_bits is None else sample_bits
        if image.ndim != 2:
            raise ConfigError(f"{self.fourcc!r} is a raw sensor format: it encodes samples (H, W), not an image "
                              f"of shape {image.shape}")
        if f.bits > bits:
            raise ConfigError(f"{self.fourcc!r} holds {f.bits} bits, more than the sensor's {bits}-bit ADC")
        v = image if f.bits == bits else (image >> (bits - f.bits))
        if f.packing == "csi2":
            return pack_csi2(v, f.bits)
        return v.astype(f.dtype, copy=False)

    def decode(self, data: bytes | np.ndarray, width: int, height: int) -> np.ndarray:
        f = self.layout
        assert f is not None
        w = self.wire(data, width, height)
        if f.packing == "csi2":
            return unpack_csi2(w, f.bits, width)
        return w.astype(np.uint16, copy=False)

    def preview(self, data: bytes | np.ndarray, width: int, height: int, levels: Levels | None = None
                ) -> np.ndarray:
        f = self.layout
        assert f is not None and f.cfa is not None
        params = levels.isp(f) if levels is not None else IspParams(white_level_dn=float((1 << f.bits) - 1))
        return preview(self.decode(data, width, height), f.cfa, params)


class _Grey(_Raw):
    """GREY: a mono sensor's 8-bit samples, or the luma of a BGR picture."""

    def encode(self, image: np.ndarray, *, sample_bits: int | None = None, quality: int = JPEG_QUALITY
               ) -> np.ndarray:
        if image.ndim == 3:
            return _cvt("COLOR_BGR2GRAY")(_as_bgr(image, self.fourcc))
        return super().encode(image, sample_bits=sample_bits)

    def preview(self, data: bytes | np.ndarray, width: int, height: int, levels: Levels | None = None
                ) -> np.ndarray:
        if levels is not None:
            return super().preview(data, width, height, levels)
        return np.repeat(self.wire(data, width, height)[..., None], 3, axis=2)


class _Jpeg(Codec):
    """MJPG: one baseline JPEG per frame, with OpenCV (libjpeg)."""

    def __init__(self) -> None:
        super().__init__("MJPG", None)

    def encode(self, image: np.ndarray, *, sample_bits: int | None = None, quality: int = JPEG_QUALITY
               ) -> np.ndarray:
        a = np.asarray(image)
        if a.dtype != np.uint8 or not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] == 3)):
            raise ConfigError(f"MJPG encodes an 8-bit BGR or grey image, got shape {a.shape} {a.dtype}")
        cv2 = _cv2()
        ok, buf = cv2.imencode(".jpg", a, [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality(quality)])
        if not ok:
            raise ConfigError(f"JPEG encoding failed for an image of shape {a.shape!r}")
        return buf.reshape(-1)

    def decode(self, data: bytes | np.ndarray, width: int | None = None, height: int | None = None
               ) -> np.ndarray:
        raw = np.frombuffer(data, np.uint8) if isinstance(data, (bytes, bytearray, memoryview)) else \
            np.ascontiguousarray(data).reshape(-1).view(np.uint8)
        cv2 = _cv2()
        img = cv2.imdecode(raw, cv2.IMREAD_COLOR) if raw.size else None
        if img is None:
            raise ProtocolError(f"MJPEG frame of {raw.size} bytes does not decode")
        return img


def bgr_to_hsv(bgr: np.ndarray) -> np.ndarray:
    """An 8-bit BGR picture in OpenCV's 8-bit HSV (hue 0..179, saturation and value 0..255)."""
    return _cv2().cvtColor(np.ascontiguousarray(bgr, np.uint8), _cv2().COLOR_BGR2HSV)


_GREY_CODES = {("bgr", 3): "COLOR_BGR2GRAY", ("bgr", 4): "COLOR_BGRA2GRAY", ("rgb", 3): "COLOR_RGB2GRAY",
               ("rgb", 4): "COLOR_RGBA2GRAY"}
"""(channel order, channels) -> OpenCV's conversion to grey (BT.601 luma)."""


def grey_u8(image: np.ndarray, order: str = "bgr") -> np.ndarray:
    """The 8-bit grey of a picture, as optical flow takes it: a 2-D one as it is, a BGR(A) one (or RGB(A), with
    ``order="rgb"``) by OpenCV's BT.601 luma; values are cast to uint8 first. ConfigError for other shapes."""
    a = np.ascontiguousarray(image, np.uint8)
    if a.ndim == 2:
        return a
    code = _GREY_CODES.get((order, a.shape[2])) if a.ndim == 3 else None
    if code is None:
        raise ConfigError(f"no grey for an {order.upper()} picture of shape {a.shape}")
    return _cvt(code)(a)


def bgr_to_rgb(image: np.ndarray) -> np.ndarray:
    """OpenCV's channel order to numpy-land's, any depth: BGR -> RGB, BGRA -> RGBA; other shapes as they are."""
    if image.ndim == 3 and image.shape[2] in (3, 4):
        return _cvt("COLOR_BGR2RGB" if image.shape[2] == 3 else "COLOR_BGRA2RGBA")(image)
    return image


def _cvt(code: str) -> Callable[[np.ndarray], np.ndarray]:
    """OpenCV's colour conversion ``code`` (imported on first use: cv2 is slow to import)."""
    def run(a: np.ndarray) -> np.ndarray:
        cv2 = _cv2()
        return cv2.cvtColor(a, getattr(cv2, code))
    return run


def _even(fourcc: str, convert: Callable[[np.ndarray], np.ndarray], both: bool) -> Callable[[np.ndarray], np.ndarray]:
    """``convert`` for chroma-subsampled ``fourcc``: even width (4:2:2), and height too (``both``, 4:2:0)."""
    def run(bgr: np.ndarray) -> np.ndarray:
        h, w = bgr.shape[:2]
        if w % 2 or (both and h % 2):
            raise ConfigError(f"{fourcc} needs an even width{' and height' if both else ''}, got {w}x{h}")
        return convert(bgr)
    return run


def _packed_422(y_first: bool) -> Callable[[np.ndarray], np.ndarray]:
    """BGR to YUYV (``y_first``) or UYVY: OpenCV's conversion byte for byte, with less CPU
    (``rollcam.sim._yuv_kernels``; imported on first use, as numba is slow to import)."""
    def run(bgr: np.ndarray) -> np.ndarray:
        from ._yuv_kernels import bgr_to_uyvy, bgr_to_yuyv

        h, w = bgr.shape[:2]
        src = np.ascontiguousarray(bgr, np.uint8)
        out = np.empty((h, w, 2), np.uint8)
        (bgr_to_yuyv if y_first else bgr_to_uyvy)(src.reshape(h, 3 * w), out.reshape(h, 2 * w))
        return out
    return run


def _bgr_to_nv12(bgr: np.ndarray) -> np.ndarray:
    """NV12 is I420 with the U and V planes interleaved (U first)."""
    i420 = _cvt("COLOR_BGR2YUV_I420")(bgr)
    h, w = bgr.shape[:2]
    out = np.empty_like(i420)
    out[:h] = i420[:h]
    chroma = i420[h:].reshape(-1)
    n = (h // 2) * (w // 2)
    uv = out[h:].reshape(-1)
    uv[0::2], uv[1::2] = chroma[:n], chroma[n:]
    return out


_PICTURES: dict[str, tuple[Callable[[np.ndarray], np.ndarray], Callable[[np.ndarray], np.ndarray]]] = {
    "bgr": (lambda b: b, lambda w: w),
    "rgb": (_cvt("COLOR_BGR2RGB"), _cvt("COLOR_RGB2BGR")),
    "xbgr": (_cvt("COLOR_BGR2BGRA"), _cvt("COLOR_BGRA2BGR")),
    "yuyv": (_even("YUYV", _packed_422(True), False), _cvt("COLOR_YUV2BGR_YUYV")),
    "uyvy": (_even("UYVY", _packed_422(False), False), _cvt("COLOR_YUV2BGR_UYVY")),
    "nv12": (_even("NV12", _bgr_to_nv12, True), _cvt("COLOR_YUV2BGR_NV12")),
    "yu12": (_even("YU12", _cvt("COLOR_BGR2YUV_I420"), True), _cvt("COLOR_YUV2BGR_I420")),
}
"""Packing -> (BGR to wire, wire to BGR): OpenCV's conversions (BT.601 limited range, as V4L2 cameras send);
the 4:2:2 packings' own kernel gives OpenCV's bytes."""


def _table() -> dict[str, Codec]:
    rows: dict[str, Codec] = {}
    for fourcc, f in FORMATS.items():
        if f.fourcc == "GREY":
            rows[fourcc] = _Grey(fourcc, f)
        elif f.is_raw:
            rows[fourcc] = _Raw(fourcc, f)
        else:
            rows[fourcc] = _Picture(fourcc, f, *_PICTURES[f.packing])
    rows["MJPG"] = _Jpeg()
    return rows


CODECS: dict[str, Codec] = _table()
"""Every fourcc rollcam encodes, decodes and previews: the rows of ``FORMATS``, and MJPG."""


def codec(fourcc: str) -> Codec:
    """The row of ``fourcc`` (a 3-letter one such as 'Y10' gets its trailing space back); ConfigError naming
    the supported fourccs when there is none."""
    key = fourcc if len(fourcc) == 4 else fourcc.ljust(4)
    try:
        return CODECS[key]
    except KeyError:
        raise ConfigError(f"pixel format {fourcc!r} has no codec; supported: {sorted(CODECS)}") from None


def preview_frame(frame: Frame, levels: Levels | None = None) -> np.ndarray:
    """The 8-bit BGR picture of ``frame``; a raw one's black level from ``levels`` or else its own meta."""
    if not frame.data.size:
        raise ConfigError(f"frame {frame.sequence} has no image: its camera sends metadata only "
                          "(insensor_output=meta)")
    if levels is None:
        levels = Levels.of_frame(frame)
    return codec(frame.format).preview(frame.data, frame.width, frame.height, levels)


def transcode(frame: Frame, fourcc: str, levels: Levels | None = None, quality: int = JPEG_QUALITY
              ) -> np.ndarray:
    """``frame`` as wire data of ``fourcc``: its data when already in it, else its preview encoded."""
    target = codec(fourcc)
    if frame.format == target.fourcc and frame.data.size:
        return frame.data
    return target.encode(preview_frame(frame, levels), quality=quality)
