"""``rollcam bench insensor``: the study's two pipelines on the same frames, scored by the same evaluation.

- **host**: the sensor sends its raw mosaic (CSI-2, the ``raw`` row of the ledger), the host runs the preview ISP
  (``rollcam.sim.codecs.preview_frame``) and a host detector on the picture (default ``personnet``);
- **in-sensor**: the camera runs its network on the raw mosaic on the chip (default ``personnet-raw``,
  ``insensor_output=meta``) and sends only its detections (the ``meta`` row).

Both see the same frames of one ``emu:`` stream (``letsroll`` 320x180, fast walkers, rolling shutter, street
scenes of their own seeds ``SCENE_SEED0..``, not those of any dataset): the stream sends the raw frame and the
in-sensor results together (``format=RGGB``, ``insensor_output=frame``), so the host pipeline's input is the
frame the network ran on, and each in-sensor result is scored against its own source frame's truth. Truth is
the datasets' labelling policy on the RS boxes; metrics are ``rollcam eval``'s (``evaluate``: P and R at best
F1, COCO mAP) with both networks at ``conf=0.01`` (mAP sees the whole curve); the detections counted as sent
are those at the network's default threshold.

The ledger is the in-sensor pipeline's as deployed: metadata only (the stream here also sends the raw frame,
for the host pipeline; that image is not charged to the in-sensor pipeline).

Latency from the frame's end of readout to detections: host = the raw frame's time on the link + the ISP and
the detector measured on this machine's CPU (one thread; a loaded machine makes these upper bounds); in-sensor
= the accelerator's modelled latency (its profile) + the detections' time on the link. Bytes and energy per
frame come from the ledger (``rollcam.firmware.ledger``), the host detector's MACs counted like the network's.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np

SCENE_SEED0 = 3000
URI = ("emu:letsroll?size=320x180&speed=fast&shutter=rolling&pedestrians=20&seed={seed}&camera={camera}"
       "&time={time}&format=RGGB&insensor={net}?conf=0.01&frames={frames}")
TIMES = ("morning", "noon", "dusk")


def _truth(frame: Any) -> Any:
    from rollcam.host.datasets.plan import LabelPolicy
    from rollcam.host.evaluation.metrics import Truth

    policy = LabelPolicy()
    boxes, ignore = [], []
    for o in frame.objects or ():
        kind = policy.classify(o.box_rs, o.visible)
        if kind is not None:
            boxes.append(o.box_rs)
            ignore.append(kind == "ignore")
    return Truth.of(boxes, [0] * len(boxes), ignore, frame.width, frame.height)


def run_insensor_bench(*, scenes: int = 4, frames: int = 8, host: str = "personnet", net: str = "personnet-raw",
                       say: Any = None) -> dict[str, Any]:
    """Both pipelines on ``scenes`` x 3 cameras x ``frames`` frames (see the module docstring)."""
    from rollcam.firmware.insensor import load_network
    from rollcam.firmware.ledger import ledger
    from rollcam.host.detectors import load_detector
    from rollcam.host.detectors.onchip import load_network as host_network
    from rollcam.host.evaluation.metrics import Dets, evaluate
    from rollcam.host.sources import open_camera
    from rollcam.sim.codecs import preview_frame

    det = load_detector(f"{host}?conf=0.01&threads=1")
    host_conf = float(load_detector(host).conf)
    net_conf = float(load_detector(net).conf)
    host_macs = host_network(host).macs(320, 180)
    truths: list[Any] = []
    host_dets: list[Any] = []
    chip: dict[tuple[int, int], Any] = {}
    frames_by_key: dict[tuple[int, int], Any] = {}
    isp_ms, det_ms, sent_counts, host_counts = [], [], [], []
    spec = None
    for s in range(scenes):
        for camera in range(3):
            uri = URI.format(seed=SCENE_SEED0 + s, camera=camera, time=TIMES[(s + camera) % 3], net=net,
                             frames=frames + 1)
            if say is not None:
                say(f"insensor bench: scene {s + 1}/{scenes}, camera {camera}")
            with open_camera(uri) as cam:
                spec = cam.spec
                for f in cam:
                    key = (s * 3 + camera, f.sequence)
                    for r in f.insensor:  # a result rides on a later frame: keep it for its own frame
                        chip[(key[0], r.seq)] = r
                    if f.sequence >= frames:
                        continue  # read only for the last result
                    frames_by_key[key] = f
                    t0 = time.perf_counter()
                    bgr = preview_frame(f)
                    t1 = time.perf_counter()
                    d = det.detect(bgr)
                    t2 = time.perf_counter()
                    isp_ms.append((t1 - t0) * 1e3)
                    det_ms.append((t2 - t1) * 1e3)
                    host_counts.append(int(np.sum(d.scores >= host_conf)))
                    truths.append(_truth(f))
                    host_dets.append(Dets.of(d.boxes, d.scores, d.classes))
    keys = list(frames_by_key)
    chip_dets, chip_truths, latencies, tensor_bytes = [], [], [], 0
    for k in keys:
        r = chip.get(k)
        if r is None:
            continue  # the accelerator skipped this frame
        chip_truths.append(_truth(frames_by_key[k]))
        chip_dets.append(Dets.of(r.boxes, r.scores, r.classes))
        sent_counts.append(int(np.sum(r.scores >= net_conf)))
        latencies.append(r.latency_ns)
        tensor_bytes = r.tensor_bytes()
    assert spec is not None
    network = load_network(spec.insensor.network)
    macs = int(network.macs(320, 180))
    # The in-sensor pipeline as deployed sends its detections only (metadata-only mode); this stream also sent the
    # raw frame, for the host pipeline to run on the same frames.
    alone = dataclasses.replace(spec, insensor=dataclasses.replace(spec.insensor, output="meta"))
    meta = ledger(alone, detections=float(np.mean(sent_counts)), tensor_bytes=tensor_bytes, macs=macs,
                  host_macs=host_macs).to_json()
    link_bps = spec.sensor.link.capacity_bps if spec.sensor.link is not None else None
    rows = meta["rows"]

    def link_ms(n_bytes: int) -> float:
        return 0.0 if link_bps is None else n_bytes * 8 / link_bps * 1e3

    host_lat = link_ms(rows["raw"]["bytes_per_frame"]) + float(np.median(isp_ms)) + float(np.median(det_ms))
    chip_lat = float(np.median(latencies)) / 1e6 + link_ms(rows["meta"]["bytes_per_frame"])
    e = meta["energy_uj_per_frame"]
    pipelines = {
        "host": {"detector": host, "input": "ISP picture (host preview ISP)", **evaluate(truths, host_dets),
                 "frames": len(truths), "bytes_per_frame": rows["raw"]["bytes_per_frame"],
                 "latency_ms": round(host_lat, 3), "isp_ms": round(float(np.median(isp_ms)), 3),
                 "detect_ms": round(float(np.median(det_ms)), 3), "macs": host_macs, "energy_uj": e["host"],
                 "detections_per_frame": round(float(np.mean(host_counts)), 2)},
        "insensor": {"detector": net, "input": "raw mosaic (no ISP)", **evaluate(chip_truths, chip_dets),
                     "frames": len(chip_truths), "bytes_per_frame": rows["meta"]["bytes_per_frame"],
                     "latency_ms": round(chip_lat, 3), "accelerator": spec.insensor.accel.name, "macs": macs,
                     "energy_uj": e["insensor"], "detections_per_frame": round(float(np.mean(sent_counts)), 2)},
    }
    ratio = rows["raw"]["bytes_per_frame"] / rows["meta"]["bytes_per_frame"]
    period_ms = 1e3 / spec.settings.timing.fps
    targets = {
        "bytes_saved": {"value": round(ratio, 1), "op": ">=", "limit": 10.0, "pass": ratio >= 10.0},
        "insensor_within_frame": {"value": round(chip_lat, 3), "op": "<=", "limit": round(period_ms, 3),
                                  "pass": chip_lat <= period_ms},
        "every_frame_inferred": {"value": len(chip_truths), "op": "==", "limit": len(truths),
                                 "pass": len(chip_truths) == len(truths)},
    }
    return {"stream": URI.format(seed=f"{SCENE_SEED0}+", camera="0..2", time="...", net=net, frames=frames + 1),
            "scenes": scenes, "frames_per_camera": frames, "pipelines": pipelines, "ledger": meta,
            "targets": targets}


def format_report(doc: dict[str, Any]) -> str:
    """The comparison as the Markdown table docs/insensor.md shows."""
    lines = ["| pipeline | network | input | frames | P | R | mAP@0.5 | mAP@0.5:0.95 | latency ms | bytes/frame "
             "off the sensor | energy uJ/frame |", "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, p in doc["pipelines"].items():
        lines.append(f"| {name} | {p['detector']} | {p['input']} | {p['frames']} | {p['P']:.3f} | {p['R']:.3f} | "
                     f"{p['mAP50']:.3f} | {p['mAP50_95']:.3f} | {p['latency_ms']:.3f} | {p['bytes_per_frame']:,} | "
                     f"{p['energy_uj']:.2f} |")
    h = doc["pipelines"]["host"]
    lines.append(f"\nhost latency = raw frame on the link + ISP {h['isp_ms']} ms + detector {h['detect_ms']} ms "
                 "(measured here, one thread); in-sensor latency = the accelerator's modelled time + detections on "
                 "the link.")
    return "\n".join(lines)
