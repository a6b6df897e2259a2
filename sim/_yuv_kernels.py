"""The numba kernels of 8-bit BGR to packed 4:2:2 (YUYV, UYVY): ``rollcam.sim.codecs``' YUYV and UYVY rows.

OpenCV's ``COLOR_BGR2YUV_YUYV`` / ``_UYVY`` conversion, byte for byte (BT.601 limited range): each pixel's
Y is ``(4211 R + 8258 G + 1606 B + 16.5 * 2**14) >> 14`` and each pair's U and V come from the pair's sums,
``(-2424 R + -4768 G + 7192 B + 128.5 * 2**15) >> 15`` and ``(7192 R - 6030 G - 1164 B + 128.5 * 2**15) >> 15``
(R, G, B: the two pixels' sums). ``tests/test_codecs.py`` holds it to OpenCV's output on random pictures and
every extreme pair. The loop reads a row as flat bytes with the byte order fixed per kernel, so it vectorises:
2.7-5.3 ms of CPU a 1080p frame on one thread against OpenCV's 6.3-6.9 (``rollcam bench uvc``), and rows run
on every numba thread.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._jitcache import guard

Y_ROUND = (16 << 14) + (1 << 13)
"""Y's offset (16) and rounding half, in 14-bit fixed point."""
C_ROUND = (128 << 15) + (1 << 14)
"""U's and V's offset (128) and rounding half, in 15-bit fixed point (the pair's sums carry one bit more)."""


@njit(inline="always")
def _pair(s, p):
    """Y0, U, Y1, V of the pixel pair at byte ``p`` of BGR row ``s``."""
    b0, g0, r0 = np.int32(s[p]), np.int32(s[p + 1]), np.int32(s[p + 2])
    b1, g1, r1 = np.int32(s[p + 3]), np.int32(s[p + 4]), np.int32(s[p + 5])
    rs, gs, bs = r0 + r1, g0 + g1, b0 + b1
    return (np.uint8((4211 * r0 + 8258 * g0 + 1606 * b0 + Y_ROUND) >> 14),
            np.uint8((-2424 * rs - 4768 * gs + 7192 * bs + C_ROUND) >> 15),
            np.uint8((4211 * r1 + 8258 * g1 + 1606 * b1 + Y_ROUND) >> 14),
            np.uint8((7192 * rs - 6030 * gs - 1164 * bs + C_ROUND) >> 15))


# One kernel per byte order: with the order a constant, each row's loop vectorises (a runtime order flag in the
# store offsets kept it scalar, at OpenCV's speed).
@njit(cache=True, parallel=True, nogil=True, boundscheck=False)
def bgr_to_yuyv(src, out):
    """Pack ``src`` (rows of B, G, R bytes: shape (H, 3 W), W even) into ``out`` ((H, 2 W) bytes), Y0 U Y1 V."""
    for i in prange(src.shape[0]):
        s, o = src[i], out[i]
        for k in range(src.shape[1] // 6):
            o[4 * k], o[4 * k + 1], o[4 * k + 2], o[4 * k + 3] = _pair(s, 6 * k)


@njit(cache=True, parallel=True, nogil=True, boundscheck=False)
def bgr_to_uyvy(src, out):
    """As ``bgr_to_yuyv``, in the order U Y0 V Y1."""
    for i in prange(src.shape[0]):
        s, o = src[i], out[i]
        for k in range(src.shape[1] // 6):
            o[4 * k + 1], o[4 * k], o[4 * k + 3], o[4 * k + 2] = _pair(s, 6 * k)


guard(__name__)
