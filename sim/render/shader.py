"""The background shader in C (``rollcam_shade.c``, built into ``librollcam_shade.so`` by the install), made
callable from the numba kernels.

The shader is C so that gcc vectorises its pixel loop (numba gives LLVM no ``noalias`` on arrays, so LLVM would
not: issue 13 round 3); it is the one copy of the background's materials, which every render path reaches
through ``world``. Loading it here, before any kernel compiles, lets numba resolve the library's
symbols by name, in a fresh compile or from its on-disk cache alike. The kernels pass arrays as addresses
(``a.ctypes.data``: an integer in the same register class as a pointer on every 64-bit ABI).
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import llvmlite.binding as llvm
from numba import types
from rollcam.common.errors import RollcamError

LIBRARY_NAME = "librollcam_shade.so"

_ADDR = types.uintp
background_line_c = types.ExternalFunction(
    "rollcam_background_line",
    types.void(_ADDR, _ADDR, types.int64, _ADDR, _ADDR, _ADDR, _ADDR, _ADDR, types.int64, _ADDR, types.int64))
"""(world, lut, n_bins, buildings, light, cam, rot, pos, line, out, n): one line of ``n`` float32 RGB pixels."""
background_span_c = types.ExternalFunction(
    "rollcam_background_span",
    types.void(_ADDR, _ADDR, types.int64, _ADDR, _ADDR, _ADDR, _ADDR, _ADDR, types.float64, types.int64, types.int64,
               _ADDR, _ADDR))
"""(world, lut, n_bins, buildings, light, cam, rot, pos, line, a_begin, a_end, out, surface): pixels a_begin ..
a_end - 1 of a line (any indices, margins beyond the image included) into ``out`` from its start, and each one's
surface code (``SURF_*``) when the ``surface`` address is not 0."""
path_reads_c = types.ExternalFunction(
    "rollcam_path_reads",
    types.void(_ADDR, types.int64, types.int64, _ADDR, _ADDR, types.int64, types.int64, types.float64,
               types.float64, types.float64, types.int64, types.int64, types.int64, _ADDR, _ADDR))
"""(bg, n_rows, n_cols, surface, coef, n, u_slot, line, lt, dt_u, transposed, margin, n_along, scratch, acc): one
line's background path reads summed into ``acc`` (``egoblur``)."""
SURF_SKY, SURF_GROUND, SURF_WEST, SURF_EAST = 0, 1, 2, 3
"""The surfaces ``background_span_c`` reports (``rollcam_shade.c``): sky, ground plane z = 0, facade planes
x = -W_FACADE and x = +W_FACADE."""
sun_blocked_c = types.ExternalFunction(
    "rollcam_sun_blocked",
    types.int64(_ADDR, _ADDR, types.int64, _ADDR, _ADDR, types.float64, types.float64, types.float64, types.int64))
"""(world, lut, n_bins, buildings, light, px, py, pz, skip_side): 1 when a facade shades point p from the sun."""


encode_line_c = types.ExternalFunction(
    "rollcam_encode_line", types.void(_ADDR, types.float64, _ADDR, types.int64, _ADDR, types.int64))
"""(lin, gain, lut, lut_size, out, n): ``n`` float32 RGB pixels to 8-bit BGR through ``lut``."""


def library_path() -> Path:
    """The built library; RollcamError (naming the fix) when the install did not build it."""
    path = Path(__file__).with_name(LIBRARY_NAME)
    if not path.is_file():
        raise RollcamError(f"{path} is missing: the install builds the renderer's background shader; reinstall "
                           "rollcam on a machine with a C compiler (in a checkout: reinstall it editable)")
    return path


def library() -> ctypes.CDLL:
    """The library through ctypes (the layout check and the tests' probes)."""
    return _LIB


def _load() -> ctypes.CDLL:
    path = str(library_path())
    llvm.load_library_permanently(path)
    lib = ctypes.CDLL(path)
    lib.rollcam_shade_layout.restype = ctypes.c_int64
    lib.rollcam_shade_layout.argtypes = [ctypes.POINTER(ctypes.c_int64), ctypes.c_int64]
    lib.rollcam_fog_transmittance.restype = ctypes.c_double
    lib.rollcam_fog_transmittance.argtypes = [ctypes.c_double]
    lib.rollcam_value_noise.restype = ctypes.c_double
    lib.rollcam_value_noise.argtypes = [ctypes.c_double, ctypes.c_double, ctypes.c_int64]
    lib.rollcam_pulse_cover.restype = ctypes.c_double
    lib.rollcam_pulse_cover.argtypes = [ctypes.c_double] * 4
    return lib


def check_layout(lib: ctypes.CDLL, expected: tuple[int, ...]) -> None:
    """Fail unless the library reads the table columns ``expected`` (``world.SHADE_LAYOUT``)."""
    buf = (ctypes.c_int64 * len(expected))()
    n = lib.rollcam_shade_layout(buf, len(expected))
    got = tuple(buf[: min(n, len(expected))])
    if n != len(expected) or got != expected:
        raise RollcamError(f"{LIBRARY_NAME} reads table columns {got} (of {n}), the renderer writes {expected}: "
                           "the library is stale; reinstall rollcam (in a checkout: reinstall it editable)")


_LIB = _load()
