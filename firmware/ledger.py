"""The energy and bandwidth ledger of one stream: bytes per frame off the sensor, link load, energy per frame.

Three things can leave a sensor each frame (``Ledger.rows``):

- ``raw``: the full mosaic at the sensor's ADC bit depth, CSI-2 packed (RAW10: 4 pixels in 5 bytes), each line a
  CSI-2 long packet (4-byte header, 2-byte CRC footer) and the frame framed by two 4-byte short packets
  (frame start, frame end): ``H * (ceil(W * bits / 8) + 6) + 8`` bytes;
- ``isp``: the ISP's picture in the stream's processed format (its V4L2 ``sizeimage``; YUYV when the stream is
  raw), in the same CSI-2 framing;
- ``meta``: the in-sensor network's detections, ``DETECTION_BYTES`` each (box, score, class as float32) with a
  ``META_HEADER_BYTES`` header (sequence, times, counts), as one long packet in the same framing;
- ``tensor``: the network's raw output tensors instead (what sending them undecoded would cost: a dense
  detection head's output can outweigh the image, which is why sensors decode on chip).

``sent`` is what this stream sends (``insensor_output``: the image and the detections, or the detections only).
Link utilisation is those bits times the frame rate over the link's capacity (``SensorConfig.link``: CSI-2
lanes x rate, or a USB bus; None when the hw_config has no link; a USB link carries the same bytes here,
without UVC's 12-byte payload headers).

Energy per frame (``EnergyModel``, figures and sources in ``ENERGY``; docs/insensor.md cites them) is counted
for the study's two pipelines: **in-sensor** (the network on the sensor's accelerator: its MACs at the
accelerator's pJ/MAC, plus the bits sent over the link) and **host** (the raw frame over the link, written to
DRAM by the receiver and read by the ISP, the ISP's picture written and read again by the detector, and the
detector's MACs at the host's pJ/MAC). The ISP's own arithmetic is not counted (no published per-pixel figure
we trust), which favours the host pipeline: the in-sensor saving shown is a lower bound on that count.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from rollcam.sim.formats import pixel_format

from .spec import CameraSpec

CSI2_LINE_OVERHEAD = 6
"""Bytes a CSI-2 long packet adds to each line: a 4-byte packet header and a 2-byte CRC footer."""
CSI2_FRAME_OVERHEAD = 8
"""Bytes of the frame start and frame end short packets (4 each)."""
META_HEADER_BYTES = 64
"""Bytes of the metadata header beside the detections: sequence number, input and done times, counts."""
DETECTION_BYTES = 24
"""Bytes of one detection: x0, y0, x1, y1, score and class, float32 each."""


@dataclass(frozen=True)
class EnergyModel:
    """Per-bit and per-operation energies, pJ (``ENERGY`` says where each comes from)."""

    link_pj_per_bit: float = 5.0
    dram_pj_per_bit: float = 1300.0 / 64
    host_pj_per_mac: float = 3.7 + 0.9


ENERGY = EnergyModel()
"""The default model: DRAM and host arithmetic from Horowitz (ISSCC 2014, 45 nm: a 64-bit DRAM access 1.3-2.6
nJ, the low end taken; a 32-bit float multiply 3.7 pJ and add 0.9 pJ, arithmetic alone, no instruction or
cache overhead); the link figure is an ASSUMPTION of the order published MIPI D-PHY transmitters report (a few
pJ/bit), to be replaced by a datasheet's; the accelerator's pJ/MAC is its profile's
(``rollcam.firmware.insensor.ACCELERATORS``)."""
SOURCES = {
    "dram_pj_per_bit": "M. Horowitz, 'Computing's energy problem', ISSCC 2014: 64-bit DRAM access 1.3-2.6 nJ",
    "host_pj_per_mac": "M. Horowitz, ISSCC 2014: 32-bit float multiply 3.7 pJ + add 0.9 pJ (45 nm)",
    "link_pj_per_bit": "assumed: the few-pJ/bit order of published MIPI D-PHY transmitters",
}


def csi2_frame_bytes(width: int, height: int, bits: int) -> int:
    """Bytes of a frame of ``height`` lines of ``width`` samples of ``bits`` bits, CSI-2 packed and framed."""
    return height * (math.ceil(width * bits / 8) + CSI2_LINE_OVERHEAD) + CSI2_FRAME_OVERHEAD


def framed(payload: int, lines: int) -> int:
    """``payload`` bytes sent as ``lines`` CSI-2 long packets in one frame."""
    return payload + lines * CSI2_LINE_OVERHEAD + CSI2_FRAME_OVERHEAD


@dataclass(frozen=True)
class Row:
    """One thing a sensor may send: bytes per frame, bit rate at the stream's frame rate, link utilisation
    (None without a link) and the link's energy per frame."""

    name: str
    bytes_per_frame: int
    mbit_s: float
    utilisation: float | None
    link_uj: float


@dataclass(frozen=True)
class Ledger:
    """A stream's ledger (see the module docstring): rows ``raw``, ``isp``, ``meta``, ``tensor``, ``sent``, and
    the energy per frame of the two pipelines."""

    sensor: str
    width: int
    height: int
    fps: float
    bits: int
    mode: str
    link: dict[str, Any] | None
    rows: dict[str, Row]
    macs: int
    insensor_uj: float
    host_uj: float
    parts: dict[str, float] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """Plain JSON."""
        return {"sensor": self.sensor, "size": f"{self.width}x{self.height}", "fps": round(self.fps, 3),
                "bits": self.bits, "mode": self.mode, "link": self.link, "macs": self.macs,
                "rows": {k: {"bytes_per_frame": r.bytes_per_frame, "mbit_s": round(r.mbit_s, 4),
                             "utilisation": None if r.utilisation is None else round(r.utilisation, 6),
                             "link_uj": round(r.link_uj, 4)} for k, r in self.rows.items()},
                "energy_uj_per_frame": {"insensor": round(self.insensor_uj, 4), "host": round(self.host_uj, 4),
                                        **{k: round(v, 4) for k, v in self.parts.items()}},
                "model": {"link_pj_per_bit": ENERGY.link_pj_per_bit, "dram_pj_per_bit": ENERGY.dram_pj_per_bit,
                          "host_pj_per_mac": ENERGY.host_pj_per_mac}}


def isp_payload(spec: CameraSpec) -> int:
    """Bytes of the ISP picture: the stream's processed format, or YUYV for a raw stream."""
    w, h = spec.size
    fourcc = "YUYV" if spec.raw else spec.pixel_format
    return pixel_format(fourcc).sizeimage(w, h)


def ledger(spec: CameraSpec, *, detections: float = 0, tensor_bytes: int = 0, macs: int | None = None,
           host_macs: int | None = None, energy: EnergyModel = ENERGY) -> Ledger:
    """The ledger of ``spec``'s stream; ``detections`` (per frame), ``tensor_bytes`` and ``macs`` describe the
    in-sensor network's output and operations per frame (a result's ``len``, ``tensor_bytes()`` and ``macs``),
    ``host_macs`` the host detector's (default: the same network's)."""
    s = spec.settings
    w, h = spec.size
    bits = spec.sensor.bit_depth
    fps = s.timing.fps
    isp_b = isp_payload(spec)
    raw_bytes = csi2_frame_bytes(w, h, bits)
    isp_bytes = framed(isp_b, h)
    meta_bytes = framed(META_HEADER_BYTES + math.ceil(detections * DETECTION_BYTES), 1)
    tensor_total = framed(META_HEADER_BYTES + tensor_bytes, 1)
    cfg = spec.insensor
    mode = "none" if cfg is None else cfg.output
    image = raw_bytes if spec.raw else isp_bytes
    sent = {"none": image, "frame": image + meta_bytes, "meta": meta_bytes}[mode]
    link = spec.sensor.link
    cap = None if link is None else link.capacity_bps

    def row(name: str, n: int) -> Row:
        bps = n * 8 * fps
        return Row(name, n, bps / 1e6, None if cap is None else bps / cap, n * 8 * energy.link_pj_per_bit / 1e6)

    rows = {"raw": row("raw", raw_bytes), "isp": row("isp", isp_bytes), "meta": row("meta", meta_bytes),
            "tensor": row("tensor", tensor_total), "sent": row("sent", sent)}
    macs = int(macs or 0)
    accel_uj = 0.0 if cfg is None else cfg.accel.energy_pj(macs) / 1e6
    hm = macs if host_macs is None else int(host_macs)
    dram_bits = 8 * (2 * raw_bytes + 2 * isp_b)  # raw in and out of DRAM for the ISP, its picture for the detector
    parts = {"insensor_accel": accel_uj, "insensor_link": rows["sent"].link_uj, "host_link": rows["raw"].link_uj,
             "host_dram": dram_bits * energy.dram_pj_per_bit / 1e6, "host_compute": hm * energy.host_pj_per_mac / 1e6}
    link_doc = None if link is None else {"bus": link.bus, "lanes": link.lanes, "lane_mbps": link.lane_mbps,
                                          "capacity_mbit_s": link.capacity_bps / 1e6}
    return Ledger(spec.sensor.name, w, h, fps, bits, mode, link_doc, rows, macs,
                  parts["insensor_accel"] + parts["insensor_link"],
                  parts["host_link"] + parts["host_dram"] + parts["host_compute"], parts)
