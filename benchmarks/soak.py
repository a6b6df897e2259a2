"""Soak benchmark: an emulated 1920x1080 30 fps rolling-shutter V4L2 device streamed in real time for minutes.

``rollcam bench soak [--minutes M]`` opens ``rollcam.emu.v4l2.Device`` on imx219 (1080p mode, frame
length for 30 fps, YUYV, street scene) in real-time mode, dequeues and re-queues buffers as an application
would, and reports:

- ``dropped``: frames missing from the V4L2 sequence (gaps), whatever the cause (the renderer falling behind,
  no queued buffer);
- frame-interval jitter: for consecutive buffers, (arrival interval on the host clock) minus (interval of
  their device timestamps), in ms: p50, p99, max of its absolute value;
- latency: arrival on the host minus the frame's due time (its last line read out), p50 / p99 / max.

Targets: 0 dropped and jitter p99 <= 2 ms (over 10 minutes in the full run). The figures depend on the
machine's load; ``machine.loadavg`` is recorded with them.
"""

from __future__ import annotations

import os
import time
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.emu.v4l2 import Device
from rollcam.emu.v4l2 import functions as fn

TARGET_JITTER_P99_MS = 2.0


def _pct(values: np.ndarray, q: float) -> float | None:
    return None if values.size == 0 else round(float(np.percentile(values, q)), 4)


def run_soak(minutes: float = 10.0, *, sensor: str = "imx219", size: tuple[int, int] = (1920, 1080),
             fps: float = 30.0, fourcc: str = "YUYV", scene: str = "street", buffers: int = 4, bands: int = 8,
             rt_priority: int | None = None, progress: Any = None) -> dict[str, Any]:
    """Stream for ``minutes`` and return the figures as a JSON-ready dict.

    ``rt_priority`` runs the device's pump waits and this reader's dequeue loop under SCHED_FIFO (as a
    real-time capture application would); None keeps the normal policy.
    """
    if not minutes > 0:
        raise ConfigError(f"soak minutes must be a positive number, got {minutes!r}")
    say = progress or (lambda _msg: None)
    arrivals, seqs, stamps = [], [], []
    reader_rt = None
    with Device.open(sensor, scene={"scene": scene}, size=size, fps=fps, realtime=True, bands=bands,
                     rt_priority=rt_priority) as dev:
        dev.set_format(*size, fourcc)
        d = dev.driver
        cam = d.camera
        n = fn.request_buffers(d, buffers)
        for i in range(n):
            fn.queue_buffer(d, i)
        # Warm the renderer (static layers, compiled kernels) before the clock starts.
        cam.stream_on()
        cam.render(cam.plan_next())
        cam.stream_off()
        fn.stream_on(d)
        if rt_priority is not None:
            reader_rt = _set_fifo(rt_priority)
        timing = cam.state.timing
        end = time.monotonic() + minutes * 60
        next_say = time.monotonic() + 10
        while time.monotonic() < end:
            buf, _view = fn.dequeue_buffer(d, timeout_s=5)
            arrivals.append(time.monotonic_ns())
            fn.queue_buffer(d, buf.index)
            seqs.append(buf.sequence)
            stamps.append(buf.timestamp_ns)
            if time.monotonic() >= next_say:
                gaps = int(np.sum(np.diff(seqs) - 1)) if len(seqs) > 1 else 0
                say(f"soak: {len(seqs)} frames, {gaps} dropped, {(end - time.monotonic()) / 60:.1f} min left")
                next_say += 10
        if reader_rt and reader_rt.startswith("SCHED_FIFO"):
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        pump_stats = d.pump.stats.to_json() if d.pump else {}
        driver_stats = d.stats.to_json()
        camera_stats = cam.stats.to_json()
        exposure_ns = int(timing.line_offset_ns(cam.state.exposure_lines))
        readout_ns = int(timing.line_offset_ns(size[1]))
        fn.stream_off(d)
        fn.request_buffers(d, 0)
    seq = np.asarray(seqs, dtype=np.int64)
    arr = np.asarray(arrivals, dtype=np.int64)
    ts = np.asarray(stamps, dtype=np.int64)
    jitter_ms = np.abs(np.diff(arr) - np.diff(ts)) / 1e6
    # Buffer timestamps are the host-monotonic start of exposure; a frame is due once its last line is out.
    latency_ms = (arr - (ts + exposure_ns + readout_ns)) / 1e6
    dropped = int(np.sum(np.diff(seq) - 1)) if seq.size > 1 else 0
    p99 = _pct(jitter_ms, 99)
    return {
        "config": {"sensor": sensor, "size": list(size), "fps": fps, "frame_period_ns": timing.frame_period_ns,
                   "line_time_ns": timing.line_time_ns, "fourcc": fourcc, "scene": scene, "buffers": n,
                   "bands": bands, "minutes": minutes, "rt_priority": rt_priority, "reader_rt": reader_rt},
        "frames": int(seq.size),
        "dropped": dropped,
        "jitter_ms": {"p50": _pct(jitter_ms, 50), "p99": p99, "max": _pct(jitter_ms, 100)},
        "latency_ms": {"p50": _pct(latency_ms, 50), "p99": _pct(latency_ms, 99), "max": _pct(latency_ms, 100)},
        "targets": {"dropped": {"op": "==", "limit": 0, "value": dropped, "pass": dropped == 0},
                    "jitter_p99_ms": {"op": "<=", "limit": TARGET_JITTER_P99_MS, "value": p99,
                                      "pass": p99 is not None and p99 <= TARGET_JITTER_P99_MS}},
        "pump": pump_stats, "driver": driver_stats, "camera": camera_stats,
        "machine": {"cpu_count": os.cpu_count(), "loadavg": list(os.getloadavg())},
    }


def _set_fifo(priority: int) -> str:
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        return f"refused: {exc}"
    return f"SCHED_FIFO {priority}"


def format_report(doc: dict[str, Any]) -> str:
    """The figures as a few lines of text."""
    c, j, lat = doc["config"], doc["jitter_ms"], doc["latency_ms"]
    verdict = {True: "PASS", False: "FAIL"}
    t = doc["targets"]
    return "\n".join([
        f"soak: {c['sensor']} {c['size'][0]}x{c['size'][1]} {c['fps']:g} fps {c['fourcc']} {c['scene']}, "
        f"{c['minutes']:g} min, real time, {c['bands']} row bands, "
        f"rt: pump {doc['pump'].get('rt')}, reader {c['reader_rt']}",
        f"frames {doc['frames']}, dropped {doc['dropped']} (skipped late {doc['camera']['skipped']}, no buffer "
        f"{doc['driver']['dropped_no_buffer']})",
        f"frame-interval jitter ms: p50 {j['p50']}  p99 {j['p99']}  max {j['max']}",
        f"latency after readout ms: p50 {lat['p50']}  p99 {lat['p99']}  max {lat['max']}",
        f"{verdict[t['dropped']['pass']]} dropped == 0; {verdict[t['jitter_p99_ms']['pass']]} jitter p99 <= "
        f"{TARGET_JITTER_P99_MS} ms   (loadavg {doc['machine']['loadavg']})",
    ])
