"""Soak benchmark: an emulated 1920x1080 30 fps rolling-shutter V4L2 device streamed in real time for minutes.

``rollcam bench soak [--minutes M] [--size WxH]`` opens ``rollcam.emu.v4l2.Device`` on imx219 (the mode for
``size``, frame length for 30 fps, YUYV, street scene) in real-time mode, dequeues and re-queues buffers as an
application would, and reports:

- ``dropped``: frames missing from the V4L2 sequence (gaps), whatever the cause (the renderer falling behind,
  no queued buffer);
- frame-interval jitter: for consecutive buffers, (arrival interval on the host clock) minus (interval of
  their device timestamps), in ms: p50, p99, max of its absolute value;
- latency: arrival on the host minus the frame's due time (its last line read out), p50 / p99 / max.

The device is the one ``open_camera("emu:imx219?...&format=YUYV")`` reads (``open_soak_device``): YUYV turns
the sensor model on with the default motion-blur bound, and ``sensor_model`` in the document says so from the
device's own spec. Targets (issue 42): 0 dropped and jitter p99 <= 2 ms (over 10 minutes in the full run). With
``hog`` the run starts a CPU hog of its own (``yes > /dev/null``: one busy process, one core, for the whole
run, killed at the end) and the target is the issue's "<= 1 % dropped at 1080p30, or 0 dropped at 720p30":
0 dropped for a frame height of 720 or less, drops <= 1 % of the frames due above it (jitter is reported, not
judged). The figures depend on the machine's load; ``machine.loadavg`` is recorded with them, and the pump's
render-ahead figures (``pump.min_ahead``: fewest frames made ahead when one was due; ``remade``;
``late_skipped``).

``run_rig_soak`` (``--cameras N``) starts ONE ``rollcam emulate --rig`` serving N cameras of one scene over
HTTP and reads every camera's MJPEG stream as a client does (multipart parts and their headers): per camera
frames, dropped (gaps in ``X-Sequence``; from the timestamps and the nominal period only for a stream without
it), jitter and latency as above (the timestamps put on the host clock by the rig's
``world_start_monotonic_ns``), and the emulator's CPU over the window; target 0 dropped per camera.

``run_memory_soak`` runs ``rollcam emulate`` (imx219 1080p30 street, MJPEG over HTTP) for minutes with one
client reading the stream and samples the process's RSS every ``every_s``: the curve, and the target of at
most ``TARGET_RSS_MB`` from the first minute on.
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError, DeviceError, RollcamError
from rollcam.common.lifecycle import Deadline, Worker
from rollcam.emu.v4l2 import Device, EmuDriver
from rollcam.emu.v4l2 import functions as fn
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.rig import SYNCS
from rollcam.firmware.spec import CameraSpec

from .http_attacks import figures as process_figures
from .http_attacks import stop as stop_process

TARGET_JITTER_P99_MS = 2.0
TARGET_HOG_DROP_FRACTION = 0.01
HOG_ZERO_DROP_MAX_HEIGHT = 720
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


def _summary(values: np.ndarray) -> dict[str, float | None]:
    return {"p50": _pct(values, 50), "p99": _pct(values, 99), "max": _pct(values, 100)}


def stream_figures(arrivals_ns: Any, seqs: Any, stamps_ns: Any, due_after_ns: Any,
                   period_ns: int | None = None) -> dict[str, Any]:
    """Frames, drops, jitter and latency of one stream as a client saw it.

    ``arrivals_ns``: host-monotonic arrival of each frame; ``seqs``: the device's frame sequence numbers, or None
    when the stream carries none (drops are then derived from the timestamps: each interval of ``k`` nominal
    periods ``period_ns`` holds ``k - 1`` lost frames); ``stamps_ns``: the device timestamps (start of exposure);
    ``due_after_ns``: exposure plus readout, so a frame is due at its timestamp plus this (latency counts from
    there; one value or one per frame). Jitter is |arrival interval - timestamp interval| of consecutive frames.
    """
    arr = np.asarray(arrivals_ns, dtype=np.int64)
    ts = np.asarray(stamps_ns, dtype=np.int64)
    if seqs is not None:
        seq = np.asarray(seqs, dtype=np.int64)
        gaps = np.diff(seq) - 1
        due = int(seq[-1] - seq[0] + 1) if seq.size else 0
        dropped_from = "sequence"
    else:
        if not period_ns or period_ns <= 0:
            raise ConfigError(f"drops from timestamps need the nominal frame period, got {period_ns!r}")
        gaps = np.rint(np.diff(ts) / period_ns).astype(np.int64) - 1
        due = int(ts.size + np.sum(np.maximum(gaps, 0)))
        dropped_from = "timestamps"
    dropped = int(np.sum(np.maximum(gaps, 0))) if gaps.size else 0
    jitter_ms = np.abs(np.diff(arr) - np.diff(ts)) / 1e6
    latency_ms = (arr - (ts + np.asarray(due_after_ns, dtype=np.int64))) / 1e6
    return {"frames": int(arr.size), "dropped": dropped, "dropped_fraction": round(dropped / max(due, 1), 6),
            "dropped_from": dropped_from, "jitter_ms": _summary(jitter_ms), "latency_ms": _summary(latency_ms)}


def soak_targets(figures: dict[str, Any], size: tuple[int, int], *, hog: bool) -> dict[str, dict[str, Any]]:
    """The one-camera soak's targets (issue 42): 0 dropped and jitter p99 <= 2 ms; under a CPU hog, 0 dropped at
    720p (a frame height of 720 or less) and <= 1 % of the frames due dropped above that (1080p)."""
    dropped, frac, p99 = figures["dropped"], figures["dropped_fraction"], figures["jitter_ms"]["p99"]
    if hog and size[1] > HOG_ZERO_DROP_MAX_HEIGHT:
        return {"dropped_fraction": {"op": "<=", "limit": TARGET_HOG_DROP_FRACTION, "value": frac,
                                     "pass": frac <= TARGET_HOG_DROP_FRACTION}}
    zero = {"dropped": {"op": "==", "limit": 0, "value": dropped, "pass": dropped == 0}}
    if hog:
        return zero
    return {**zero, "jitter_p99_ms": {"op": "<=", "limit": TARGET_JITTER_P99_MS, "value": p99,
                                      "pass": p99 is not None and p99 <= TARGET_JITTER_P99_MS}}


def open_soak_device(sensor: str = "imx219", *, size: tuple[int, int] = (1920, 1080), fps: float = 30.0,
                     fourcc: str = "YUYV", scene: str = "street", bands: int = 8,
                     rt_priority: int | None = None) -> Device:
    """The soak's real-time V4L2 device on the camera ``open_camera`` builds from
    ``emu:SENSOR?scene=..&size=WxH&fps=..&format=FOURCC`` (the same ``CameraSpec``, so for YUYV the sensor model
    with the default blur bound), its format set by VIDIOC_S_FMT as an application does."""
    options = {"scene": scene, "size": f"{size[0]}x{size[1]}", "fps": f"{fps:g}", "format": fourcc}
    spec = CameraSpec.from_options(sensor, options, "bench soak")
    dev = Device(EmuDriver(FirmwareCamera(spec), realtime=True, bands=bands, rt_priority=rt_priority))
    try:
        dev.set_format(*size, fourcc)
    except BaseException:
        dev.close()
        raise
    return dev


def sensor_model(spec: Any) -> dict[str, Any]:
    """What a camera spec's frames go through: the sensor model (on or off), its motion-blur bound, the format."""
    return {"physics": spec.uses_physics, "blur_px": spec.blur_px, "ego_blur": spec.ego_blur,
            "pixel_format": spec.pixel_format}


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
    with cpu_hog(hog) as hog_info, open_soak_device(sensor, size=size, fps=fps, fourcc=fourcc, scene=scene,
                                                    bands=bands, rt_priority=rt_priority) as dev:
        d = dev.driver
        cam = d.camera
        model = sensor_model(cam.spec)
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
    figures = stream_figures(arrivals, seqs, stamps, exposure_ns + readout_ns)
    targets = soak_targets(figures, size, hog=hog)
    return {
        "config": {"sensor": sensor, "size": list(size), "fps": fps, "frame_period_ns": timing.frame_period_ns,
                   "line_time_ns": timing.line_time_ns, "fourcc": fourcc, "scene": scene, "buffers": n,
                   "bands": bands, "minutes": minutes, "rt_priority": rt_priority, "reader_rt": reader_rt,
                   "hog": hog_info},
        "sensor_model": model,
        **figures,
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
    c, j, lat, m = doc["config"], doc["jitter_ms"], doc["latency_ms"], doc["sensor_model"]
    verdict = {True: "PASS", False: "FAIL"}
    p = doc["pump"]
    checks = "; ".join(f"{verdict[t['pass']]} {name} {t['op']} {t['limit']} ({t['value']})"
                       for name, t in doc["targets"].items())
    return "\n".join([
        f"soak: {c['sensor']} {c['size'][0]}x{c['size'][1]} {c['fps']:g} fps {c['fourcc']} {c['scene']}, "
        f"{c['minutes']:g} min, real time, {c['bands']} row bands, "
        f"rt: pump {p.get('rt')}, reader {c['reader_rt']}" + (f", under a CPU hog ({c['hog']['command']})"
                                                             if c.get("hog") else ""),
        f"sensor model {'on' if m['physics'] else 'off'} (blur bound {m['blur_px']:g} px, ego blur {m['ego_blur']})",
        f"frames {doc['frames']}, dropped {doc['dropped']} ({doc['dropped_fraction']:.3%}; skipped late "
        f"{doc['camera']['skipped']}, no buffer {doc['driver']['dropped_no_buffer']}); render-ahead: fewest made "
        f"ahead {p.get('min_ahead')}, remade {p.get('remade')}, late {p.get('late_skipped')}",
        f"frame-interval jitter ms: p50 {j['p50']}  p99 {j['p99']}  max {j['max']}",
        f"latency after readout ms: p50 {lat['p50']}  p99 {lat['p99']}  max {lat['max']}",
        f"{checks}   (loadavg {doc['machine']['loadavg']})",
    ])


RIG_WARMUP_S = 2.0
"""Seconds the rig soak reads every stream before its window opens (first frames, connection set-up)."""
MAX_RIG_CAMERAS = 16


def rig_text(cameras: int, sync: str) -> str:
    """The ``--rig`` declaration of ``cameras`` cameras (a stereo pair for 2, a surround rig otherwise)."""
    if not 2 <= cameras <= MAX_RIG_CAMERAS:
        raise ConfigError(f"bench soak: --cameras {cameras!r} is not in 2..{MAX_RIG_CAMERAS} (a rig's cameras)")
    if sync not in SYNCS:
        raise ConfigError(f"bench soak: --sync {sync!r} is not one of {SYNCS}")
    return f"stereo,sync={sync}" if cameras == 2 else f"surround,n={cameras},sync={sync}"


class StreamLog:
    """What one MJPEG client saw: per part its arrival (host monotonic ns) and the headers that time it."""

    def __init__(self, url: str, clock_to_host_ns: int = 0) -> None:
        self.url = url
        self.clock_to_host_ns = clock_to_host_ns  # added to a device timestamp, the host's monotonic reading
        self.arrivals: list[int] = []
        self.seqs: list[int | None] = []
        self.stamps: list[int] = []
        self.due_after: list[int] = []
        self.not_jpeg = 0
        self.ended: str | None = None  # why the stream ended before the reader was told to stop
        self.ended_ns: int | None = None

    def read(self, stopping: Any, height: int, timeout_s: float = 30.0) -> None:
        """Read parts until ``stopping()`` or the stream ends, as a client of the camera would."""
        from urllib.request import urlopen

        from rollcam.host.sources.http import MjpegParser, boundary_of

        try:
            with urlopen(self.url, timeout=timeout_s) as resp:
                parser = MjpegParser(resp, boundary_of(resp.headers.get("Content-Type", "")))
                while not stopping():
                    part = parser.next_part()
                    now = time.monotonic_ns()
                    if part is None:
                        self._end("the stream ended", stopping)
                        return
                    self.add(now, *part, height=height)
        except (OSError, RollcamError, ValueError) as exc:
            self._end(f"{type(exc).__name__}: {exc}", stopping)

    def _end(self, why: str, stopping: Any) -> None:
        if not stopping():
            self.ended, self.ended_ns = why, time.monotonic_ns()

    def add(self, arrival_ns: int, headers: dict[str, str], body: bytes, *, height: int) -> None:
        """One part (headers lower-cased, as ``MjpegParser`` gives them) that arrived at ``arrival_ns``."""
        seq = headers.get("x-sequence")
        self.arrivals.append(arrival_ns)
        self.seqs.append(int(seq) if seq is not None else None)
        self.stamps.append(int(headers["x-timestamp-ns"]) + self.clock_to_host_ns)
        self.due_after.append(int(headers.get("x-exposure-ns", 0)) + int(headers.get("x-line-time-ns", 0)) * height)
        self.not_jpeg += not body.startswith(b"\xff\xd8")

    def figures(self, start_ns: int, end_ns: int, period_ns: int | None) -> dict[str, Any]:
        """``stream_figures`` of the parts that arrived in [start_ns, end_ns]; a stream that ended early has the
        frames due between its last part and ``end_ns`` (by the nominal period) counted as dropped too."""
        keep = [i for i, t in enumerate(self.arrivals) if start_ns <= t <= end_ns]
        seqs = [self.seqs[i] for i in keep]
        stamps = [self.stamps[i] for i in keep]
        if period_ns is None and len(stamps) > 1:
            period_ns = int(np.median(np.diff(stamps)))  # only used when the stream carries no sequence
        doc = stream_figures([self.arrivals[i] for i in keep], None if None in seqs else seqs, stamps,
                             [self.due_after[i] for i in keep], period_ns)
        lost_tail = 0
        ended = self.ended if self.ended_ns is not None and self.ended_ns <= end_ns else None
        if ended is not None and period_ns:
            last = self.arrivals[keep[-1]] if keep else start_ns
            lost_tail = max(0, (end_ns - last) // period_ns)
        doc["dropped"] += int(lost_tail)
        doc["lost_after_end"] = int(lost_tail)
        doc["ended"] = ended
        doc["not_jpeg"] = self.not_jpeg
        return doc


def run_rig_soak(minutes: float = 5.0, *, cameras: int = 2, size: tuple[int, int] = (1280, 720), fps: float = 30.0,
                 scene: str = "street", sync: str = "free", physics: bool = True, faults: str | None = None,
                 progress: Any = None) -> dict[str, Any]:
    """Serve a ``cameras``-camera rig from ONE ``rollcam emulate --rig`` process and read every camera's MJPEG
    stream over HTTP for ``minutes``: per camera frames, dropped (gaps in ``X-Sequence``), jitter, latency; the
    process's CPU; target 0 dropped per camera. ``physics``: the sensor model on (default blur bound); ``faults``:
    a fault plan passed to the emulator (its ``drop`` loses parts, which the figures must count)."""
    if not minutes > 0:
        raise ConfigError(f"soak minutes must be a positive number, got {minutes!r}")
    rig = rig_text(cameras, sync)
    say = progress or (lambda _msg: None)
    window_s = minutes * 60
    cmd = [sys.executable, "-m", "rollcam.host.cli", "emulate", "imx219", "--size", f"{size[0]}x{size[1]}",
           "--fps", f"{fps:g}", "--scene", scene, "--physics", "on" if physics else "off", "--rig", rig,
           "--http", "127.0.0.1:0", "--json", "--duration", f"{window_s + RIG_WARMUP_S + 120:g}"]
    if faults:
        cmd += ["--faults", faults]
    logs: list[StreamLog] = []
    workers: list[Worker] = []
    stop = threading.Event()
    with tempfile.TemporaryFile() as errors:
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=errors, text=True)
        try:
            endpoints = _endpoints(proc, errors)
            world0 = int(endpoints["rig"]["world_start_monotonic_ns"])  # the cameras' clocks: no offset, no drift
            for i, cam in enumerate(endpoints["cameras"]):
                log = StreamLog(cam["http"]["url"], world0)
                logs.append(log)
                workers.append(Worker(log.read, stop.is_set, size[1], name=f"soak-camera-{i}", stop_event=stop).start())
            first = Deadline(60)
            while not all(log.arrivals for log in logs):
                if first.expired or proc.poll() is not None or any(log.ended for log in logs):
                    raise DeviceError(f"rig soak: not every camera's stream delivered a frame "
                                      f"({[len(log.arrivals) for log in logs]} parts; {_tail(proc, errors)})")
                time.sleep(0.05)
            time.sleep(RIG_WARMUP_S)
            cpu0, start_ns = process_figures(proc.pid)["cpu_s"], time.monotonic_ns()
            deadline, say_at = Deadline(window_s), Deadline(10)
            while not deadline.expired and proc.poll() is None:
                time.sleep(min(0.5, deadline.remaining() or 0))
                if say_at.expired:
                    say(f"rig soak: {[len(log.arrivals) for log in logs]} parts, "
                        f"{(deadline.remaining() or 0) / 60:.1f} min left")
                    say_at.restart()
            end_ns = time.monotonic_ns()
            cpu_s = process_figures(proc.pid)["cpu_s"] - cpu0 if proc.poll() is None else None
            exited = proc.poll()
            servers = [_status(cam["http"]["url"]) for cam in endpoints["cameras"]]
        finally:
            stop.set()
            stop_process(proc)
            for worker in workers:  # the connections closed with the process; their readers end
                with contextlib.suppress(Exception):
                    worker.close()
        if exited is not None:
            raise DeviceError(f"rig soak: rollcam emulate exited ({exited}) during the run: {_tail(proc, errors)}")
        errors.seek(0)
        emulate_report = [line for line in errors.read().decode(errors="replace").splitlines() if "stopped;" in line]
    per_camera = [{**log.figures(start_ns, end_ns, None), "server": server} for log, server in zip(logs, servers,
                                                                                                    strict=True)]
    wall_s = (end_ns - start_ns) / 1e9
    targets = {f"camera{i}_dropped": {"op": "==", "limit": 0, "value": c["dropped"], "pass": c["dropped"] == 0}
               for i, c in enumerate(per_camera)}
    return {"config": {"command": " ".join(["rollcam", *cmd[3:]]), "cameras": cameras, "rig": rig,
                       "size": list(size), "fps": fps, "scene": scene, "physics": physics, "faults": faults,
                       "minutes": minutes, "warmup_s": RIG_WARMUP_S, "emulate_pid": proc.pid},
            "wall_s": round(wall_s, 2), "per_camera": per_camera,
            "emulate_cpu": {"cpu_s": round(cpu_s, 2) if cpu_s is not None else None,
                            "cores": round(cpu_s / wall_s, 3) if cpu_s is not None and wall_s > 0 else None},
            "emulate_report": emulate_report,
            "targets": targets,
            "machine": {"cpu_count": os.cpu_count(), "loadavg": list(os.getloadavg())}}


def _status(stream_url: str) -> dict[str, Any] | None:
    """The MJPEG server's counters (``/status.json`` beside the stream: frames encoded, parts dropped for slow
    clients, the pump's and the camera's counters), or None when it does not answer."""
    from urllib.parse import urljoin
    from urllib.request import urlopen

    try:
        with urlopen(urljoin(stream_url, "/status.json"), timeout=5) as resp:
            doc = json.loads(resp.read())
    except (OSError, ValueError):
        return None
    keys = ("frames_encoded", "dropped_total", "send_timeouts", "pump", "camera")
    return {k: doc.get(k) for k in keys} if isinstance(doc, dict) else None


def _endpoints(proc: subprocess.Popen, errors: Any, timeout_s: float = 300.0) -> dict[str, Any]:
    """The ``--json`` line ``rollcam emulate`` prints once its servers are up (compiling kernels may come first)."""
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], timeout_s)
    line = proc.stdout.readline() if ready else ""
    try:
        doc = json.loads(line)
        return {"rig": doc["rig"], "cameras": doc["cameras"]}
    except (json.JSONDecodeError, KeyError, TypeError):
        raise DeviceError(f"rig soak: rollcam emulate printed no endpoints ({_tail(proc, errors)})") from None


def _tail(proc: subprocess.Popen, errors: Any) -> str:
    """The emulator's last stderr line (or its exit status), for an error message."""
    errors.seek(0)
    lines = errors.read().decode(errors="replace").strip().splitlines()
    return lines[-1] if lines else f"exit status {proc.poll()}"


def format_rig_report(doc: dict[str, Any]) -> str:
    """The rig soak as a few lines of text."""
    c, cpu = doc["config"], doc["emulate_cpu"]
    lines = [f"rig soak: one '{c['command']}', {c['cameras']} cameras {c['size'][0]}x{c['size'][1]} {c['fps']:g} fps "
             f"{c['scene']}, sensor model {'on' if c['physics'] else 'off'}, {doc['wall_s']:g} s read over HTTP; "
             f"emulate CPU {cpu['cpu_s']} s ({cpu['cores']} cores)"]
    lines += [f"  emulate: {line}" for line in doc.get("emulate_report", ())]
    for i, f in enumerate(doc["per_camera"]):
        j, lat = f["jitter_ms"], f["latency_ms"]
        lines.append(f"  camera {i}: frames {f['frames']}, dropped {f['dropped']} ({f['dropped_fraction']:.3%}, "
                     f"from the {f['dropped_from']}){'; ended: ' + f['ended'] if f['ended'] else ''}; jitter ms "
                     f"p50 {j['p50']} p99 {j['p99']} max {j['max']}; latency ms p50 {lat['p50']} p99 {lat['p99']} "
                     f"max {lat['max']}")
    verdict = {True: "PASS", False: "FAIL"}
    lines.append("; ".join(f"{verdict[t['pass']]} {name} {t['op']} {t['limit']} ({t['value']})"
                           for name, t in doc["targets"].items()) + f"   (loadavg {doc['machine']['loadavg']})")
    return "\n".join(lines)


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
        reader = Worker(_read_stream, url, stop, got, name="memory-soak-reader", stop_event=stop)
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
