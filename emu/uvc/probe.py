"""The VideoStreaming probe/commit control (UVC 1.5 table 4-75) in its 26, 34 and 48-byte forms."""

from __future__ import annotations

import struct
from dataclasses import astuple, dataclass, replace

from rollcam.common.errors import ProtocolError

from .constants import PROBE_LEN_10, PROBE_LEN_11, PROBE_LEN_15, PROBE_LENGTHS

_V10 = struct.Struct("<HBBIHHHHHII")  # 26 bytes: UVC 1.0
_V11 = struct.Struct("<IBBBB")  # +8: dwClockFrequency, bmFramingInfo, bPreferedVersion, bMinVersion, bMaxVersion
_V15 = struct.Struct("<BBBBHQ")  # +14: bUsage .. bmLayoutPerStream


@dataclass(frozen=True)
class Probe:
    """One probe/commit structure; fields are the specification's, in its order."""

    bmHint: int = 0
    bFormatIndex: int = 0
    bFrameIndex: int = 0
    dwFrameInterval: int = 0
    wKeyFrameRate: int = 0
    wPFrameRate: int = 0
    wCompQuality: int = 0
    wCompWindowSize: int = 0
    wDelay: int = 0
    dwMaxVideoFrameSize: int = 0
    dwMaxPayloadTransferSize: int = 0
    dwClockFrequency: int = 0
    bmFramingInfo: int = 0
    bPreferedVersion: int = 0
    bMinVersion: int = 0
    bMaxVersion: int = 0
    bUsage: int = 0
    bBitDepthLuma: int = 0
    bmSettings: int = 0
    bMaxNumberOfRefFramesPlus1: int = 0
    bmRateControlModes: int = 0
    bmLayoutPerStream: int = 0

    def pack(self, length: int = PROBE_LEN_15) -> bytes:
        """The control's bytes, truncated to a 26/34/48-byte form (UVC 1.0/1.1/1.5)."""
        if length not in PROBE_LENGTHS:
            raise ProtocolError(f"probe length {length!r} is not one of {PROBE_LENGTHS}")
        v = astuple(self)
        try:
            raw = _V10.pack(*v[:11]) + _V11.pack(*v[11:16]) + _V15.pack(*v[16:])
        except struct.error as exc:
            raise ProtocolError(f"probe field out of range: {exc}") from None
        return raw[:length]

    @classmethod
    def unpack(cls, data: bytes) -> Probe:
        """Parse a 26, 34 or 48-byte control; fields a shorter form lacks are zero."""
        n = len(data)
        if n not in PROBE_LENGTHS:
            raise ProtocolError(f"probe control of {n!r} bytes; expected one of {PROBE_LENGTHS}")
        raw = bytes(data) + bytes(PROBE_LEN_15 - n)
        v = _V10.unpack_from(raw, 0) + _V11.unpack_from(raw, PROBE_LEN_10) + _V15.unpack_from(raw, PROBE_LEN_11)
        return cls(*v)

    def with_(self, **fields: int) -> Probe:
        """A copy with ``fields`` replaced."""
        return replace(self, **fields)


__all__ = ["PROBE_LENGTHS", "PROBE_LEN_10", "PROBE_LEN_11", "PROBE_LEN_15", "Probe"]
