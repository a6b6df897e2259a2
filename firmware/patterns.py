"""Sensor test patterns (colour bars, solid colour, fade-to-grey bars, PN9, walking ones) as BGR images.

A pattern replaces the scene at the sensor's output, the same on every frame, as on the real parts.
"""

from __future__ import annotations

import functools

import numpy as np
from rollcam.common.errors import ConfigError

_BARS_BGR = np.array([[255, 255, 255], [0, 255, 255], [255, 255, 0], [0, 255, 0],
                      [255, 0, 255], [0, 0, 255], [255, 0, 0], [0, 0, 0]], dtype=np.uint8)
"""SMPTE-order 100 % bars: white, yellow, cyan, green, magenta, red, blue, black (BGR)."""


def _bars(width: int, height: int) -> np.ndarray:
    idx = np.arange(width) * len(_BARS_BGR) // width
    return np.broadcast_to(_BARS_BGR[idx], (height, width, 3)).copy()


def _fade_bars(width: int, height: int) -> np.ndarray:
    bars = _bars(width, height).astype(np.float32)
    fade = (np.arange(height, dtype=np.float32) / max(height - 1, 1))[:, None, None]
    return np.rint(bars * (1 - fade) + 128.0 * fade).astype(np.uint8)


def _solid(width: int, height: int) -> np.ndarray:
    return np.full((height, width, 3), 128, dtype=np.uint8)


@functools.cache
def _pn9_bits(n: int) -> np.ndarray:
    """The PRBS9 sequence (x^9 + x^5 + 1, seed all ones), ``n`` bits."""
    state, out = 0x1FF, np.empty(n, dtype=np.uint8)
    for i in range(n):
        bit = ((state >> 8) ^ (state >> 4)) & 1
        out[i] = state & 1
        state = ((state << 1) | bit) & 0x1FF
    return out


def _pn9(width: int, height: int) -> np.ndarray:
    period = 511  # the sequence repeats; one period of bytes, tiled, is the whole pattern
    bits = _pn9_bits(period * 8).reshape(period, 8)
    values = (bits * (1 << np.arange(8, dtype=np.uint8))).sum(axis=1).astype(np.uint8)
    flat = np.resize(values, width * height)
    return np.repeat(flat.reshape(height, width)[:, :, None], 3, axis=2)


def _walking_ones(width: int, height: int) -> np.ndarray:
    col = (1 << (np.arange(width) % 8)).astype(np.uint8)
    return np.broadcast_to(col[None, :, None], (height, width, 3)).copy()


PATTERNS = {"bars": _bars, "fade_bars": _fade_bars, "solid": _solid, "pn9": _pn9, "walking_ones": _walking_ones}


@functools.lru_cache(maxsize=8)
def _cached(name: str, width: int, height: int) -> np.ndarray:
    img = PATTERNS[name](width, height)
    img.setflags(write=False)
    return img


def render_pattern(name: str, width: int, height: int) -> np.ndarray:
    """The BGR image (read-only, cached) of test pattern ``name`` at ``width`` x ``height``."""
    if name not in PATTERNS:
        raise ConfigError(f"test pattern {name!r} is not one of {sorted(PATTERNS)}")
    return _cached(name, int(width), int(height))
