"""Files from other people that claim more than they hold: headers declaring huge images, for the loaders' tests."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np


def png_header_only(path: Path, width: int, height: int) -> None:
    """A PNG whose IHDR declares ``width`` x ``height`` (16-bit grey) with one tiny IDAT: 1 KB on disk, the size
    claimed only in the header (the attack of issue 37, a 0.9 MB file of zeros, decoded to 1.9 GB)."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", width, height, 16, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(bytes(1024)))
                     + chunk(b"IEND", b""))


def npy_header_only(path: Path, shape: tuple[int, ...]) -> None:
    """A ``.npy`` whose header declares ``shape`` of uint16, with no data."""
    with path.open("wb") as f:
        np.lib.format.write_array_header_1_0(f, {"descr": "<u2", "fortran_order": False, "shape": shape})
