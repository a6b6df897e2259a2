"""Soak benchmark: an emulated 1920x1080 30 fps rolling-shutter V4L2 device streamed in real time for minutes.

``rollcam bench soak [--minutes M]`` opens ``rollcam.emu.v4l2.Device`` on imx219 (1080p mode, frame
length for 30 fps, YUYV, street scene) in real-time mode, dequeues and re-queues buffers as an application
would, and reports:

- ``dropped``: frames missing from the V4L2 sequence (gaps), whatever the cause (the renderer falling behind,
  no queued buffer);
- frame-interval jitter: for consecutive buffers, (arrival interval on the host clock) minus (interval of
  their device timestamps), in ms: p50, p99, max of its absolute value;
- latency: arrival on the host minus the frame's due time (its last line read out), p50 / p99 / max.

Targets: 0 dropped and jitter p99 <= 2 ms (over 10 minutes in the full run). With ``hog`` the run starts
a CPU hog of its own (``yes > /dev/null``: one busy process, one core, for the whole run, killed at the
end) and the target is drops <= 0.1 % of the frames due (jitter is reported, not judged). The figures depend
on the machine's load; ``machine.loadavg`` is recorded with them, and the pump's render-ahead figures
(``pump.min_ahead``: fewest frames made ahead when one was due; ``remade``; ``late_skipped``).

``run_memory_soak`` runs ``rollcam emulate`` (imx219 1080p30 street, MJPEG over HTTP) for minutes with one
client reading the stream and samples the process's RSS every ``every_s``: the curve, and the target of at
most ``TARGET_RSS_MB`` from the first minute on.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.common.lifecycle import Deadline
from rollcam.emu.v4l2 import Device
from rollcam.emu.v4l2 import functions as fn

from .http_attacks import stop as stop_process

TARGET_JITTER_P99_MS = 2.0
TARGET_HOG_DROP_FRACTION = 0.001
TARGET_RSS_MB = 500.0


@contextlib.contextmanager
def cpu_hog(on: bool) -> Iterator[dict[str, Any] | None]:
    """A ``yes > /dev/null`` process for the block (one core kept busy), ended by its pid after it."""
    if not on:
        yield None
        return
    proc = subprocess.Popen(["yes"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        yield {"command": "yes > /dev/null", "pid": proc.pid}
    finally:
        proc.kill()
        proc.wait(10)


def _pct(values: np.ndarray, q: float) -> float | None:
    return None if values.size == 0 else round(float(np.percentile(values, q)), 4)


def run_soak(minutes: float = 10.0, *, sensor: str = "imx219", size: tuple[int, int] = (1920, 1080),
             fps: float = 30.0, fourcc: str = "YUYV", scene: str = "street", buffers: int = 4, bands: int = 8,
             rt_priority: int | None = None, progress: Any = None, hog: bool = False) -> dict[str, Any]:
    """Stream for ``minutes`` and return the figures as a JSON-ready dict (``hog``: under a CPU hog).

    ``rt_priority`` runs the device's pump waits and this reader's dequeue loop under SCHED_FIFO (as a
    real-time capture application would); None keeps the normal policy.
    """
    if not minutes > 0:
        raise ConfigError(f"soak minutes must be a positive number, got {minutes!r}")
    say = progress or (lambda _msg: None)
    arrivals, seqs, stamps = [], [], []
    reader_rt = None
    with cpu_hog(hog) as hog_info, Device.open(sensor, scene={"scene": scene}, size=size, fps=fps, realtime=True,
                                               bands=bands, rt_priority=rt_priority) as dev:
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
        deadline, say_at = Deadline(minutes * 60), Deadline(10)
        while not deadline.expired:
            buf, _view = fn.dequeue_buffer(d, timeout_s=5)
            arrivals.append(time.monotonic_ns())
            fn.queue_buffer(d, buf.index)
            seqs.append(buf.sequence)
            stamps.append(buf.timestamp_ns)
            if say_at.expired:
                gaps = int(np.sum(np.diff(seqs) - 1)) if len(seqs) > 1 else 0
                say(f"soak: {len(seqs)} frames, {gaps} dropped, {(deadline.remaining() or 0) / 60:.1f} min left")
                say_at.restart()
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
    due = int(seq[-1] - seq[0] + 1) if seq.size else 0
    p99 = _pct(jitter_ms, 99)
    frac = round(dropped / max(due, 1), 6)
    if hog:
        targets = {"dropped_fraction": {"op": "<=", "limit": TARGET_HOG_DROP_FRACTION, "value": frac,
                                        "pass": frac <= TARGET_HOG_DROP_FRACTION}}
    else:
        targets = {"dropped": {"op": "==", "limit": 0, "value": dropped, "pass": dropped == 0},
                   "jitter_p99_ms": {"op": "<=", "limit": TARGET_JITTER_P99_MS, "value": p99,
                                     "pass": p99 is not None and p99 <= TARGET_JITTER_P99_MS}}
    return {
        "config": {"sensor": sensor, "size": list(size), "fps": fps, "frame_period_ns": timing.frame_period_ns,
                   "line_time_ns": timing.line_time_ns, "fourcc": fourcc, "scene": scene, "buffers": n,
                   "bands": bands, "minutes": minutes, "rt_priority": rt_priority, "reader_rt": reader_rt,
                   "hog": hog_info},
        "frames": int(seq.size),
        "dropped": dropped,
        "dropped_fraction": frac,
        "jitter_ms": {"p50": _pct(jitter_ms, 50), "p99": p99, "max": _pct(jitter_ms, 100)},
        "latency_ms": {"p50": _pct(latency_ms, 50), "p99": _pct(latency_ms, 99), "max": _pct(latency_ms, 100)},
        "targets": targets,
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
    p = doc["pump"]
    checks = "; ".join(f"{verdict[t['pass']]} {name} {t['op']} {t['limit']} ({t['value']})"
                       for name, t in doc["targets"].items())
    return "\n".join([
        f"soak: {c['sensor']} {c['size'][0]}x{c['size'][1]} {c['fps']:g} fps {c['fourcc']} {c['scene']}, "
        f"{c['minutes']:g} min, real time, {c['bands']} row bands, "
        f"rt: pump {p.get('rt')}, reader {c['reader_rt']}" + (f", under a CPU hog ({c['hog']['command']})"
                                                             if c.get("hog") else ""),
        f"frames {doc['frames']}, dropped {doc['dropped']} ({doc['dropped_fraction']:.3%}; skipped late "
        f"{doc['camera']['skipped']}, no buffer {doc['driver']['dropped_no_buffer']}); render-ahead: fewest made "
        f"ahead {p.get('min_ahead')}, remade {p.get('remade')}, late {p.get('late_skipped')}",
        f"frame-interval jitter ms: p50 {j['p50']}  p99 {j['p99']}  max {j['max']}",
        f"latency after readout ms: p50 {lat['p50']}  p99 {lat['p99']}  max {lat['max']}",
        f"{checks}   (loadavg {doc['machine']['loadavg']})",
    ])


def _rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def run_memory_soak(minutes: float = 10.0, *, every_s: float = 10.0, size: tuple[int, int] = (1920, 1080),
                    progress: Any = None) -> dict[str, Any]:
    """``rollcam emulate`` at ``size`` with one MJPEG reader for ``minutes``: its RSS curve (module docstring)."""
    if not minutes > 0:
        raise ConfigError(f"soak minutes must be a positive number, got {minutes!r}")
    say = progress or (lambda _msg: None)
    cmd = [sys.executable, "-m", "rollcam.host.cli", "emulate", "imx219", "--size", f"{size[0]}x{size[1]}",
           "--fps", "30", "--http", "127.0.0.1:0", "--json", "--duration", str(minutes * 60 + 30)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    curve: list[tuple[float, float]] = []
    stop = threading.Event()
    got = [0]
    try:
        assert proc.stdout is not None
        endpoints = json.loads(proc.stdout.readline())
        url = endpoints["http"]["url"]
        reader = threading.Thread(target=_read_stream, args=(url, stop, got), daemon=True)
        t0 = time.monotonic()
        reader.start()
        end = t0 + minutes * 60
        while time.monotonic() < end and proc.poll() is None:
            curve.append((round(time.monotonic() - t0, 1), round(_rss_mb(proc.pid), 1)))
            say(f"memory soak: {curve[-1][1]} MB RSS after {curve[-1][0]:.0f} s, {got[0]} parts read")
            time.sleep(every_s)
        curve.append((round(time.monotonic() - t0, 1), round(_rss_mb(proc.pid), 1)))
    finally:
        stop.set()
        stop_process(proc)
    steady = [mb for t, mb in curve if t >= min(60.0, minutes * 30)]
    peak = max(steady) if steady else None
    command = f"rollcam emulate imx219 --size {size[0]}x{size[1]} --fps 30 --http"
    return {"config": {"command": command, "minutes": minutes, "every_s": every_s},
            "rss_mb": curve, "parts_read": got[0],
            "steady": {"min": min(steady) if steady else None, "max": peak,
                       "growth_mb": round(steady[-1] - steady[0], 1) if steady else None},
            "targets": {"rss_mb_max": {"op": "<=", "limit": TARGET_RSS_MB, "value": peak,
                                       "pass": peak is not None and peak <= TARGET_RSS_MB}},
            "machine": {"cpu_count": os.cpu_count(), "loadavg": list(os.getloadavg())}}


def _read_stream(url: str, stop: threading.Event, got: list[int]) -> None:
    """Read the MJPEG stream at ``url`` until ``stop`` (counting parts), as a viewer does."""
    import urllib.request

    with contextlib.suppress(OSError), urllib.request.urlopen(url, timeout=30) as resp:
        while not stop.is_set():
            chunk = resp.read(1 << 16)
            if not chunk:
                return
            got[0] += chunk.count(b"--rollcamframe")


def format_memory_report(doc: dict[str, Any]) -> str:
    """The memory soak as a few lines of text."""
    s, t = doc["steady"], doc["targets"]["rss_mb_max"]
    curve = " ".join(f"{int(sec)}s:{mb:.0f}" for sec, mb in doc["rss_mb"])
    return "\n".join([
        f"memory soak: {doc['config']['command']}, {doc['config']['minutes']:g} min, {doc['parts_read']} MJPEG "
        f"parts read; RSS MB from the first minute: min {s['min']} max {s['max']} growth {s['growth_mb']}",
        f"  curve (s:MB): {curve}",
        f"{'PASS' if t['pass'] else 'FAIL'} RSS <= {TARGET_RSS_MB:g} MB   (loadavg {doc['machine']['loadavg']})"])
