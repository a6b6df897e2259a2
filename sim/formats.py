"""V4L2 pixel formats the emulated sensor delivers: the fourcc table, CSI-2 packing, the Bayer mosaic.

Layouts follow the kernel's documentation (Documentation/userspace-api/media/v4l/pixfmt-*):

- 8-bit Bayer / GREY: ``uint8 (H, W)``.
- 10/12/16-bit unpacked (RG10, RG12, Y10, Y12, Y16, ...): ``uint16 (H, W)``, little-endian, value in the low
  bits (a 10-bit sample 0..1023 stays 0..1023).
- MIPI CSI-2 packed (pRAA, pRCC, Y10P, ...): ``uint8 (H, bytesperline)``. 10-bit: every 4 pixels take 5
  bytes, the 8 high bits of each pixel then one byte of their 2 low bits (pixel 0 in bits 1:0). 12-bit: every
  2 pixels take 3 bytes, the 8 high bits of each then one byte with pixel 0's low nibble in bits 3:0.
- YUYV / UYVY: ``uint8 (H, W, 2)`` (Y0 U0 Y1 V0 ... / U0 Y0 V0 Y1 ...), NV12: ``uint8 (H * 3 / 2, W)`` (Y plane,
  then interleaved UV), YU12: ``uint8 (H * 3 / 2, W)`` (Y, U, V planes), BGR3 / RGB3: ``uint8 (H, W, 3)``,
  XR24: ``uint8 (H, W, 4)`` (B G R X).

How frames of each fourcc are encoded, decoded and previewed is ``rollcam.sim.codecs``, the table beside this one.

Flips change a Bayer sensor's order as a real sensor's do (``flipped_order``): the readout starts on
another colour of the 2x2 tile.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from rollcam.common.errors import ConfigError

from ._jitcache import guard

BAYER_ORDERS = ("RGGB", "BGGR", "GRBG", "GBRG")
_BAYER_FOURCCS = {  # order -> fourcc of 8, 10, 10 packed, 12, 12 packed, 16 bits (V4L2_PIX_FMT_S*)
    "RGGB": ("RGGB", "RG10", "pRAA", "RG12", "pRCC", "RG16"),
    "BGGR": ("BA81", "BG10", "pBAA", "BG12", "pBCC", "BYR2"),
    "GRBG": ("GRBG", "BA10", "pgAA", "BA12", "pgCC", "GR16"),
    "GBRG": ("GBRG", "GB10", "pGAA", "GB12", "pGCC", "GB16"),
}
_BAYER_LAYOUTS = (("raw", 8), ("raw", 10), ("csi2", 10), ("raw", 12), ("csi2", 12), ("raw", 16))


YUV_PACKINGS = ("yuyv", "uyvy", "nv12", "yu12")
"""The Y'CbCr layouts: BT.601 limited range, as ``rollcam.sim.codecs`` converts them."""


@dataclass(frozen=True)
class PixelFormat:
    """One fourcc: sample bits, memory layout (``packing``) and colour filter (Bayer order, 'mono' or None).

    ``packing`` is 'raw' (one sample per pixel, uint8 up to 8 bits, else uint16), 'csi2' (MIPI CSI-2 packed),
    'yuyv', 'uyvy', 'nv12', 'yu12', 'bgr', 'rgb' or 'xbgr'.
    """

    fourcc: str
    bits: int
    packing: str
    cfa: str | None

    @property
    def is_raw(self) -> bool:
        """True for sensor samples (Bayer or mono), False for formats an ISP produces."""
        return self.cfa is not None

    def bytesperline(self, width: int) -> int:
        """Bytes of one line of the first plane (V4L2 ``bytesperline``), unpadded."""
        per = {"raw": 1 if self.bits <= 8 else 2, "yuyv": 2, "uyvy": 2, "nv12": 1, "yu12": 1, "bgr": 3, "rgb": 3,
               "xbgr": 4}
        if self.packing == "csi2":
            return math.ceil(width * self.bits / 8)
        return width * per[self.packing]

    def sizeimage(self, width: int, height: int) -> int:
        """Bytes of a whole frame (V4L2 ``sizeimage``)."""
        if self.packing in ("nv12", "yu12"):
            return width * height * 3 // 2
        return self.bytesperline(width) * height

    def line_spans(self, first: int, end: int, width: int, height: int) -> list[tuple[int, int]]:
        """Byte ranges ``[lo, hi)`` of a frame that hold image lines ``first..end-1``, in every plane: a band of
        a 4:2:0 frame (NV12, YU12) is its luma lines and the chroma lines they share (chroma line ``k`` serves
        lines ``2k`` and ``2k + 1``), so a device that fills a buffer band by band fills the chroma too."""
        luma = self.bytesperline(width)
        spans = [(first * luma, end * luma)]
        if self.packing in ("nv12", "yu12"):
            c0, c1 = first // 2, (end + 1) // 2  # the chroma lines the band touches
            y_size = luma * height
            if self.packing == "nv12":  # one plane of interleaved CbCr, a line as wide as luma's
                spans.append((y_size + c0 * luma, y_size + c1 * luma))
            else:  # Cb then Cr planes, half as wide and half as high
                half = luma // 2
                cb_size = half * (height // 2)
                spans += [(y_size + c0 * half, y_size + c1 * half),
                          (y_size + cb_size + c0 * half, y_size + cb_size + c1 * half)]
        return spans

    def shape(self, width: int, height: int) -> tuple[int, ...]:
        """Array shape of a frame's ``data`` in this format."""
        if self.packing in ("nv12", "yu12"):
            return (height * 3 // 2, width)
        if self.packing in ("yuyv", "uyvy"):
            return (height, width, 2)
        if self.packing in ("bgr", "rgb"):
            return (height, width, 3)
        if self.packing == "xbgr":
            return (height, width, 4)
        return (height, self.bytesperline(width)) if self.packing == "csi2" else (height, width)

    @property
    def dtype(self) -> type:
        """numpy dtype of ``data``."""
        return np.uint16 if self.packing == "raw" and self.bits > 8 else np.uint8


FORMATS: dict[str, PixelFormat] = {
    **{f: PixelFormat(f, bits, packing, order)
       for order, fs in _BAYER_FOURCCS.items() for f, (packing, bits) in zip(fs, _BAYER_LAYOUTS, strict=True)},
    "GREY": PixelFormat("GREY", 8, "raw", "mono"), "Y10 ": PixelFormat("Y10 ", 10, "raw", "mono"),
    "Y12 ": PixelFormat("Y12 ", 12, "raw", "mono"), "Y16 ": PixelFormat("Y16 ", 16, "raw", "mono"),
    "Y10P": PixelFormat("Y10P", 10, "csi2", "mono"), "Y12P": PixelFormat("Y12P", 12, "csi2", "mono"),
    "YUYV": PixelFormat("YUYV", 8, "yuyv", None), "UYVY": PixelFormat("UYVY", 8, "uyvy", None),
    "NV12": PixelFormat("NV12", 8, "nv12", None), "YU12": PixelFormat("YU12", 8, "yu12", None),
    "BGR3": PixelFormat("BGR3", 8, "bgr", None), "RGB3": PixelFormat("RGB3", 8, "rgb", None),
    "XR24": PixelFormat("XR24", 8, "xbgr", None),
}
"""Every fourcc the emulated sensor can deliver. GREY is the mono sensor's 8-bit output; a colour stream
asked for GREY gets the ISP's luma (see ``rollcam.sim.isp``)."""


def pixel_format(fourcc: str) -> PixelFormat:
    """The table row of ``fourcc`` (a 3-letter one such as 'Y10' gets its trailing space back)."""
    key = fourcc if len(fourcc) == 4 else fourcc.ljust(4)
    try:
        return FORMATS[key]
    except KeyError:
        raise ConfigError(f"pixel format {fourcc!r} is not one the emulator produces; known: {sorted(FORMATS)}"
                          ) from None


def bayer_fourcc(order: str, bits: int, packed: bool = False) -> str:
    """The fourcc of Bayer ``order`` at ``bits`` (8, 10, 12, 16), CSI-2 packed or not; mono gives Y../GREY."""
    for f in FORMATS.values():
        if f.cfa == order and f.bits == bits and (f.packing == "csi2") == packed:
            return f.fourcc
    raise ConfigError(f"no {'packed ' if packed else ''}{bits}-bit format for CFA {order!r}")


def flipped_order(order: str, hflip: bool = False, vflip: bool = False) -> str:
    """Bayer order read out with horizontal and/or vertical flip (RGGB + hflip -> GRBG, + vflip -> GBRG)."""
    if order == "mono":
        return order
    if order not in BAYER_ORDERS:
        raise ConfigError(f"Bayer order {order!r} is not one of {list(BAYER_ORDERS)} or 'mono'")
    tile = [order[0:2], order[2:4]]
    if vflip:
        tile = tile[::-1]
    if hflip:
        tile = [row[::-1] for row in tile]
    return tile[0] + tile[1]


_CHANNEL = {"B": 0, "G": 1, "R": 2}  # index in a BGR image


def cfa_channels(order: str, rgb: bool = False) -> np.ndarray:
    """2x2 int array: the image channel each position of the Bayer tile samples (BGR indices, or RGB)."""
    idx = np.array([_CHANNEL[c] for c in order], np.int64).reshape(2, 2)
    return 2 - idx if rgb else idx


def mosaic(image: np.ndarray, order: str, *, rgb: bool = False) -> np.ndarray:
    """Sample a 3-channel image (BGR, or RGB with ``rgb``) through a Bayer filter of ``order`` -> (H, W).

    'mono' gives Rec. 709 luma weights of the three channels (a mono sensor sees all colours).
    """
    if image.ndim != 3 or image.shape[2] != 3:
        raise ConfigError(f"mosaic needs an (H, W, 3) image, got shape {image.shape}")
    if order == "mono":
        w = np.array([0.0722, 0.7152, 0.2126] if not rgb else [0.2126, 0.7152, 0.0722], np.float32)
        out = image.astype(np.float32) @ w
        return out.astype(image.dtype) if np.issubdtype(image.dtype, np.floating) else \
            np.round(out).astype(image.dtype)
    ch = cfa_channels(order, rgb)
    out = np.empty(image.shape[:2], image.dtype)
    for dy in (0, 1):
        for dx in (0, 1):
            out[dy::2, dx::2] = image[dy::2, dx::2, ch[dy, dx]]
    return out


# ------------------------------------------------------------------------------------------ CSI-2 packing
@njit(cache=True)
def _pack10(v, out):
    h, w = v.shape
    for y in range(h):
        for g in range(w // 4):
            x, b = 4 * g, 5 * g
            low = 0
            for i in range(4):
                s = v[y, x + i]
                out[y, b + i] = (s >> 2) & 0xFF
                low |= (s & 3) << (2 * i)
            out[y, b + 4] = low
        r = w % 4
        if r:
            x, b = w - r, 5 * (w // 4)
            low = 0
            for i in range(r):
                s = v[y, x + i]
                out[y, b + i] = (s >> 2) & 0xFF
                low |= (s & 3) << (2 * i)
            out[y, b + r] = low


@njit(cache=True)
def _unpack10(p, out):
    h, w = out.shape
    for y in range(h):
        for x in range(w):
            g, i = x // 4, x % 4
            n = min(4, w - 4 * g)
            out[y, x] = (np.uint16(p[y, 5 * g + i]) << 2) | ((p[y, 5 * g + n] >> (2 * i)) & 3)


@njit(cache=True)
def _pack12(v, out):
    h, w = v.shape
    for y in range(h):
        for g in range((w + 1) // 2):
            x, b = 2 * g, 3 * g
            s0 = v[y, x]
            s1 = v[y, x + 1] if x + 1 < w else 0
            out[y, b] = (s0 >> 4) & 0xFF
            if x + 1 < w:
                out[y, b + 1] = (s1 >> 4) & 0xFF
                out[y, b + 2] = (s0 & 0xF) | ((s1 & 0xF) << 4)
            else:
                out[y, b + 1] = s0 & 0xF


@njit(cache=True)
def _unpack12(p, out):
    h, w = out.shape
    for y in range(h):
        for x in range(w):
            g, i = x // 2, x % 2
            n = 2 if 2 * g + 1 < w else 1
            out[y, x] = (np.uint16(p[y, 3 * g + i]) << 4) | ((p[y, 3 * g + n] >> (4 * i)) & 0xF)


def pack_csi2(values: np.ndarray, bits: int) -> np.ndarray:
    """MIPI CSI-2 RAW10 / RAW12 packing of ``uint16 (H, W)`` samples -> ``uint8 (H, ceil(W * bits / 8))``."""
    if bits not in (10, 12):
        raise ConfigError(f"CSI-2 packing is defined here for 10 and 12 bits, not {bits!r}")
    v = np.ascontiguousarray(values, dtype=np.uint16)
    if v.ndim != 2:
        raise ConfigError(f"pack_csi2 needs (H, W) samples, got shape {v.shape}")
    out = np.empty((v.shape[0], math.ceil(v.shape[1] * bits / 8)), np.uint8)
    (_pack10 if bits == 10 else _pack12)(v, out)
    return out


def unpack_csi2(packed: np.ndarray, bits: int, width: int) -> np.ndarray:
    """Inverse of ``pack_csi2``: ``uint8 (H, bytesperline)`` -> ``uint16 (H, width)``."""
    if bits not in (10, 12):
        raise ConfigError(f"CSI-2 unpacking is defined here for 10 and 12 bits, not {bits!r}")
    p = np.ascontiguousarray(packed, dtype=np.uint8)
    need = math.ceil(width * bits / 8)
    if p.ndim != 2 or p.shape[1] < need:
        raise ConfigError(f"{width} pixels of {bits}-bit CSI-2 need (H, >= {need}) bytes, got shape {p.shape}")
    out = np.empty((p.shape[0], width), np.uint16)
    (_unpack10 if bits == 10 else _unpack12)(p, out)
    return out


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
