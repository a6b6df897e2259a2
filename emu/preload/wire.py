"""The preload wire format, read from its one definition: ``rollcam_wire.h`` beside this file, which the C
library includes. The device server (``rollcam.emu.v4l2.server``) uses these names; the header's comment says
what each operation carries.
"""

from __future__ import annotations

import enum
import re
import struct
from pathlib import Path

from rollcam.common.errors import DeviceError

HEADER = Path(__file__).with_name("rollcam_wire.h")
_FIELD_CODES = {"uint32_t": "I", "int32_t": "i", "uint64_t": "Q", "int64_t": "q"}


def _parse(text: str) -> tuple[dict[str, int], dict[str, int], dict[str, struct.Struct]]:
    """(defines, ops, structs) of the header's subset of C (see its comment)."""
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    defines = {m[1]: int(m[2], 0) for m in re.finditer(r"#define ROLLCAM_WIRE_(\w+)\s+(0x[0-9a-fA-F]+|\d+)", text)}
    body = re.search(r"enum rollcam_op\s*\{(.*?)\};", text, re.S)
    if body is None:
        raise DeviceError(f"{HEADER}: no enum rollcam_op")
    ops = {m[1]: int(m[2], 0) for m in re.finditer(r"OP_(\w+)\s*=\s*(\d+)", body[1])}
    structs = {}
    for m in re.finditer(r"struct rollcam_(\w+)\s*\{(.*?)\};", text, re.S):
        codes = []
        for decl in filter(None, (d.strip() for d in m[2].split(";"))):
            kind, _, names = decl.partition(" ")
            if kind not in _FIELD_CODES:
                raise DeviceError(f"{HEADER}: struct rollcam_{m[1]} has a field of type {kind!r}")
            codes += [_FIELD_CODES[kind]] * len(names.split(","))
        structs[m[1]] = struct.Struct("=" + "".join(codes))
    return defines, ops, structs


_DEFINES, _OPS, _STRUCTS = _parse(HEADER.read_text())

MAGIC: int = _DEFINES["MAGIC"]
VERSION: int = _DEFINES["VERSION"]
MAX_PAYLOAD: int = _DEFINES["MAX_PAYLOAD"]
MAX_FDS: int = _DEFINES["MAX_FDS"]
Op = enum.IntEnum("Op", _OPS)
"""The operations (``Op.OPEN`` ... ``Op.ATTACH``)."""
HELLO: struct.Struct = _STRUCTS["hello"]
"""``{magic, version}``: the first thing each side sends on a connection."""
REQ: struct.Struct = _STRUCTS["req"]
"""A request: ``op, len, a, b, c`` then ``len`` payload bytes."""
RSP: struct.Struct = _STRUCTS["rsp"]
"""An answer: ``result, err, len`` then ``len`` bytes."""
