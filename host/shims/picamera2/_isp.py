"""The Pi's ISP, emulated: one raw sensor frame -> the configured streams' arrays (raw, main, lores).

The raw stream is the sensor's frame as the CSI-2 receiver stores it (``uint8 (height, stride)``: packed bytes
for ``*_CSI2P``, two little-endian bytes per sample, value in the low bits, for unpacked formats). ``main`` and
``lores`` are one ISP picture: the raw samples through the firmware's preview ISP (black level, white level
of the frame's gain, white balance, demosaic, sRGB; ``rollcam.sim.isp``) exactly as the firmware camera makes
its processed formats, cropped to ``ScalerCrop`` and scaled to each stream's size, then laid out in the
stream's format (YUV through the codec table, ``rollcam.sim.codecs``). Strides have no padding.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from rollcam.sim import formats as sf
from rollcam.sim.codecs import codec
from rollcam.sim.frame import Frame
from rollcam.sim.isp import IspParams, preview

RGB_LAYOUTS = {"RGB888": ("bgr", False), "BGR888": ("rgb", False), "XRGB8888": ("bgr", True),
               "XBGR8888": ("rgb", True)}
"""libcamera's RGB formats as byte orders in memory: RGB888 is B, G, R (what OpenCV calls BGR)."""

YUV_CODECS = {"YUV420": "YU12", "YVU420": "YU12", "NV12": "NV12", "NV21": "NV12", "YUYV": "YUYV",
              "YVYU": "YUYV", "UYVY": "UYVY", "VYUY": "UYVY"}
"""YUV formats -> the codec whose layout they share (the second of each pair has U and V swapped)."""

SUPPORTED = set(RGB_LAYOUTS) | set(YUV_CODECS)
"""Processed formats the emulated ISP writes (not RGB161616/BGR161616 or MJPEG)."""


def stride_and_size(fmt: str, size: tuple[int, int], raw_fourcc: str | None = None) -> tuple[int, int]:
    """Bytes per line and per frame of a stream (no padding)."""
    w, h = size
    if raw_fourcc is not None:
        layout = sf.pixel_format(raw_fourcc)
        stride = layout.bytesperline(w)
        return stride, stride * h
    if fmt in RGB_LAYOUTS:
        stride = w * (4 if RGB_LAYOUTS[fmt][1] else 3)
        return stride, stride * h
    if fmt in ("YUYV", "YVYU", "UYVY", "VYUY"):
        return 2 * w, 2 * w * h
    return w, w * h * 3 // 2


def raw_array(frame: Frame) -> np.ndarray:
    """The raw frame as the receiver's buffer: ``uint8 (height, stride)``."""
    return np.ascontiguousarray(frame.data).view(np.uint8).reshape(frame.height, -1)


def isp_picture(frame: Frame, isp: IspParams, bit_depth: int, bayer_order: str,
                colour_gains: tuple[float, float] | None = None) -> np.ndarray:
    """The ISP's 8-bit BGR picture of a raw frame (at the sensor mode's size)."""
    layout = sf.pixel_format(frame.format)
    samples = codec(frame.format).decode(frame.data, frame.width, frame.height)
    if layout.bits < bit_depth:  # a narrower format keeps the ADC's high bits: back to ADC units
        samples = samples.astype(np.uint16) << (bit_depth - layout.bits)
    if colour_gains is not None:
        isp = dataclasses.replace(isp, wb_gains=(float(colour_gains[0]), 1.0, float(colour_gains[1])))
    return preview(samples, bayer_order, isp)


def crop_pixels(crop: tuple[int, int, int, int], limits: tuple[int, int, int, int],
                size: tuple[int, int]) -> tuple[int, int, int, int]:
    """A ScalerCrop (pixel-array coordinates) as a rectangle of the mode's image of ``size``, clipped to it."""
    lx, ly, lw, lh = limits
    w, h = size
    x0 = round((crop[0] - lx) * w / lw)
    y0 = round((crop[1] - ly) * h / lh)
    x1 = round((crop[0] + crop[2] - lx) * w / lw)
    y1 = round((crop[1] + crop[3] - ly) * h / lh)
    x0, y0 = min(max(x0, 0), w - 2), min(max(y0, 0), h - 2)
    x1, y1 = min(max(x1, x0 + 2), w), min(max(y1, y0 + 2), h)
    return x0, y0, x1 - x0, y1 - y0


def aspect_crop(limits: tuple[int, int, int, int], out_size: tuple[int, int]) -> tuple[int, int, int, int]:
    """The largest centred rectangle of ``limits`` with the output's aspect ratio (``preserve_ar``)."""
    x, y, w, h = limits
    ow, oh = out_size
    if w * oh > h * ow:  # the field is wider than the output: trim the sides
        cw = h * ow // oh
        return (x + (w - cw) // 2, y, cw, h)
    ch = w * oh // ow
    return (x, y + (h - ch) // 2, w, ch)


def scaled(picture: np.ndarray, rect: tuple[int, int, int, int], size: tuple[int, int]) -> np.ndarray:
    """``rect`` of the picture scaled to ``size`` (area averaging down, bilinear up)."""
    import cv2

    x, y, w, h = rect
    part = picture[y:y + h, x:x + w]
    if (w, h) == tuple(size):
        return part
    down = size[0] <= w and size[1] <= h
    return cv2.resize(part, tuple(size), interpolation=cv2.INTER_AREA if down else cv2.INTER_LINEAR)


def layout(bgr: np.ndarray, fmt: str) -> np.ndarray:
    """An 8-bit BGR picture in a stream format's array shape (as picamera2's ``make_array`` gives it)."""
    if fmt in RGB_LAYOUTS:
        order, alpha = RGB_LAYOUTS[fmt]
        img = bgr if order == "bgr" else bgr[..., ::-1]
        if alpha:
            out = np.empty((*img.shape[:2], 4), np.uint8)
            out[..., :3] = img
            out[..., 3] = 255
            return out
        return np.ascontiguousarray(img)
    data = np.ascontiguousarray(codec(YUV_CODECS[fmt]).encode(np.ascontiguousarray(bgr)))
    h, w = bgr.shape[:2]
    if fmt == "YVU420":  # the U and V planes swap places
        flat = data.reshape(-1)
        q = (w // 2) * (h // 2)
        flat[w * h:w * h + q], flat[w * h + q:] = flat[w * h + q:].copy(), flat[w * h:w * h + q].copy()
    elif fmt == "NV21":
        uv = data[h:].reshape(h // 2, w // 2, 2)
        data[h:] = uv[..., ::-1].reshape(h // 2, w)
    elif fmt in ("YVYU", "VYUY"):
        c = 1 if fmt == "YVYU" else 0  # the channel that alternates U, V
        u = data[:, 0::2, c].copy()
        data[:, 0::2, c] = data[:, 1::2, c]
        data[:, 1::2, c] = u
    return data


def stream_arrays(frame: Frame, streams: dict[str, Any], picture_of: Any) -> dict[str, np.ndarray]:
    """Arrays of every configured stream; ``streams`` maps a name to (format, size, crop rect) (raw: None) and
    ``picture_of()`` makes the ISP picture (only when a processed stream needs it)."""
    out: dict[str, np.ndarray] = {}
    picture = None
    for name, spec in streams.items():
        if spec is None:
            out[name] = raw_array(frame)
            continue
        fmt, size, rect = spec
        if picture is None:
            picture = picture_of()
        out[name] = layout(scaled(picture, rect, size), fmt)
    return out
