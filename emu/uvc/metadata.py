"""In-sensor results in the UVC payload header: a vendor metadata item after the standard 12 header bytes.

UVC 1.5 lets ``bHeaderLength`` run past the standard fields (up to 255 bytes); Microsoft's UVC extension
(MSXU 1.5 metadata) fills that space with metadata items, each a ``KSCAMERA_METADATA_ITEMHEADER`` (``u32``
MetadataId, ``u32`` Size, the item included), custom ids from 0x80000000. Hosts read it there: Windows' camera
stack as frame metadata, Linux's uvcvideo on its metadata node when the node's format keeps the whole header
(the plain ``UVCH`` format keeps the standard 12 bytes only). The emulated camera puts one item,
``RCIS_ITEM_ID``, in the first payload of each frame that carries an in-sensor result (the newest one, as on
the other transports), little-endian:

- ``u32`` MetadataId ``0x80000001``, ``u32`` Size;
- ``u8`` version 1, ``u8`` results (1), ``u8`` detections, ``u8`` flags (bit 0: detections were cut to fit);
- ``u32`` PTS of the source frame's start of exposure, ``u32`` its input complete, ``u32`` the result done:
  ticks of ``dwClockFrequency`` modulo 2**32, the clock of the header's PTS (so the host relates them to it);
- ``u16`` sequence difference (this frame's device sequence minus the source frame's), ``u16`` x ``u16`` the
  network's input size, ``u16`` reserved;
- per detection (10 bytes, best first, at most ``MAX_DETECTIONS``): ``u16`` x0, y0, x1, y1 in the frame's
  pixels (rounded, clipped to 65535), ``u8`` score x 255, ``u8`` class.
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np

from .payload import HEADER_LEN, NS_PER_S, ns_to_ticks

RCIS_ITEM_ID = 0x80000001
"""The item's MetadataId: the first of the custom range (MetadataId_Custom)."""
VERSION = 1
ITEM = struct.Struct("<IIBBBBIIIHHHH")
DETECTION = struct.Struct("<HHHHBB")
MAX_HEADER = 255
MAX_DETECTIONS = (MAX_HEADER - HEADER_LEN - ITEM.size) // DETECTION.size
"""Detections that fit a 255-byte payload header (21)."""
TRUNCATED = 1


def encode(results: tuple[Any, ...] | list[Any], frame_seq: int, clock_hz: int) -> bytes:
    """The item of a frame's newest in-sensor result (b"" when it carries none)."""
    if not results:
        return b""
    r = results[-1]
    order = np.argsort(-r.scores, kind="stable")
    k = min(len(order), MAX_DETECTIONS)
    dets = b"".join(
        DETECTION.pack(*(int(min(max(round(float(v)), 0), 0xFFFF)) for v in r.boxes[i]),
                       int(round(float(np.clip(r.scores[i], 0, 1)) * 255)), int(r.classes[i]) & 0xFF)
        for i in order[:k])
    w, h = (min(int(v), 0xFFFF) for v in r.input_size)
    size = ITEM.size + len(dets)
    head = ITEM.pack(RCIS_ITEM_ID, size, VERSION, 1, k, TRUNCATED if len(order) > k else 0,
                     *(ns_to_ticks(int(t), clock_hz) & 0xFFFFFFFF for t in (r.timestamp_ns, r.input_ns, r.done_ns)),
                     min(max(frame_seq - int(r.seq), 0), 0xFFFF), w, h, 0)
    return head + dets


def decode(extra: bytes, clock_hz: int) -> dict[str, Any] | None:
    """The rollcam item among the metadata items ``extra`` (a payload header's bytes after the standard 12),
    or None when there is none; times come back as ticks and as ns modulo the 32-bit tick range."""
    pos = 0
    while pos + 8 <= len(extra):
        item_id, size = struct.unpack_from("<II", extra, pos)
        if size < 8 or pos + size > len(extra):
            return None
        if item_id == RCIS_ITEM_ID and size >= ITEM.size:
            (_, _, version, _n, k, flags, t0, t_in, t_done, dseq, w, h, _) = ITEM.unpack_from(extra, pos)
            if version != VERSION or size < ITEM.size + k * DETECTION.size:
                return None
            dets = [DETECTION.unpack_from(extra, pos + ITEM.size + i * DETECTION.size) for i in range(k)]
            return {"timestamp_ticks": t0, "input_ticks": t_in, "done_ticks": t_done, "frames_before": dseq,
                    "input_size": (w, h), "truncated": bool(flags & TRUNCATED),
                    "detections": [{"box": list(d[:4]), "score": d[4] / 255, "cls": d[5]} for d in dets]}
        pos += size
    return None


def _ticks_before(ticks_now: int, ticks: int) -> int:
    """Signed ticks from ``ticks`` to ``ticks_now`` on the 32-bit tick counter (within 2**31 either way)."""
    d = (ticks_now - ticks) & 0xFFFFFFFF
    return d - (1 << 32) if d >= 1 << 31 else d


def to_result(item: dict[str, Any], pts: int, pts_ns: int, clock_hz: int, seq: int, *, line_time_ns: int = 0,
              readout: str = "top_to_bottom", exposure_ns: int = 0, network: str = "") -> Any:
    """An ``InSensorResult`` of a decoded item on a frame of PTS ``pts`` (raw ticks) and ``pts_ns`` (the
    host's full device time of that PTS) and sequence ``seq``: the item's ticks become device ns beside it."""
    from rollcam.sim.insensor import InSensorResult

    def ns(ticks: int) -> int:
        d = _ticks_before(pts, ticks)
        step = (abs(d) * NS_PER_S + clock_hz - 1) // clock_hz  # exact at 1 GHz
        return pts_ns - step if d >= 0 else pts_ns + step

    dets = item["detections"]
    return InSensorResult(seq=seq - item["frames_before"], boxes=[d["box"] for d in dets],
                          scores=[d["score"] for d in dets], classes=[d["cls"] for d in dets],
                          timestamp_ns=ns(item["timestamp_ticks"]), line_time_ns=line_time_ns, readout=readout,
                          exposure_ns=exposure_ns, input_ns=ns(item["input_ticks"]), done_ns=ns(item["done_ticks"]),
                          input_size=tuple(item["input_size"]), network=network)
