"""Per-frame cost of the preload path: ``rollcam bench preload``.

A child program under the preload library streams a 1920x1080 YUYV device (frames made when DQBUF asks,
``realtime=False``) with ``ioctl`` DQBUF/QBUF on ``/dev/video0``, reading each frame in place in its mapped
buffer, and times each DQBUF+QBUF; the server times the making of that same frame (render, encode and the
one fill into the shared buffer). Per frame, the difference is what the preload path adds: the socket round
trips, the ioctl decoding on both sides and the program's own calls. Target: <= 2 ms per frame (median).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from typing import Any

import numpy as np

WIDTH, HEIGHT = 1920, 1080
SOURCE = f"emu:imx219?size={WIDTH}x{HEIGHT}&format=YUYV&test_pattern=bars"
TARGET_MS = 2.0

_CLIENT = r"""
import fcntl, json, mmap, os, sys, time
from rollcam.emu.v4l2 import abi
R = {k: v[0] for k, v in abi.REQUESTS.items()}
frames = int(sys.argv[1])
fd = os.open("/dev/video0", os.O_RDWR)
fcntl.ioctl(fd, R["REQBUFS"], abi.RequestBuffers(count=4, type=1, memory=1))
maps = []
for i in range(4):
    b = abi.Buffer(index=i, type=1, memory=1)
    fcntl.ioctl(fd, R["QUERYBUF"], b)
    maps.append(mmap.mmap(fd, b.length, mmap.MAP_SHARED, mmap.PROT_READ, offset=b.m.offset))
    fcntl.ioctl(fd, R["QBUF"], b)
fcntl.ioctl(fd, R["STREAMON"], abi.C.c_int(1))
times, checks = [], 0
b = abi.Buffer(type=1, memory=1)
for n in range(frames + 2):
    t0 = time.perf_counter_ns()
    fcntl.ioctl(fd, R["DQBUF"], b)
    checks += maps[b.index][b.bytesused // 2]  # touch the frame where it lies: no copy
    fcntl.ioctl(fd, R["QBUF"], b)
    if n >= 2:
        times.append(time.perf_counter_ns() - t0)
fcntl.ioctl(fd, R["STREAMOFF"], abi.C.c_int(1))
print(json.dumps({"times_ns": times, "bytesused": b.bytesused}))
"""


def _round(frames: int) -> tuple[list[int], list[int]]:
    """One stream of ``frames``: the program's DQBUF+QBUF time of each frame, and the time the server spent
    making that frame (render, encode, fill: ``EmuDriver.produce_now``, which each DQBUF runs once)."""
    from rollcam.host.servers.devnodes import program_environment, serving

    made: list[int] = []
    with serving([("/dev/video0", SOURCE)], realtime=False) as server:
        driver = server.nodes["/dev/video0"].driver
        produce = driver.produce_now

        def timed() -> bool:
            t0 = time.perf_counter_ns()
            try:
                return produce()
            finally:
                made.append(time.perf_counter_ns() - t0)

        driver.produce_now = timed
        p = subprocess.run([sys.executable, "-c", _CLIENT, str(frames)], env=program_environment(server),
                           capture_output=True, text=True, timeout=600, check=False)
    if p.returncode != 0:
        raise RuntimeError(f"the preload client failed ({p.returncode}): {p.stderr[-2000:]}")
    doc = json.loads(p.stdout.strip().splitlines()[-1])
    if doc["bytesused"] != WIDTH * HEIGHT * 2:
        raise RuntimeError(f"the preload client got {doc['bytesused']} bytes a frame")
    return doc["times_ns"], made[2:2 + frames]


def run_preload_bench(frames: int = 30, rounds: int = 2, say: Any = print) -> dict[str, Any]:
    """Per frame: the program's time minus the server's time making that same frame; medians over frames."""
    client: list[int] = []
    made: list[int] = []
    for r in range(rounds):
        say(f"round {r + 1}/{rounds}")
        c, m = _round(frames)
        client += c
        made += m
    over = np.array(client, float) - np.array(made, float)
    overhead = float(np.median(over)) / 1e6
    return {"config": {"size": f"{WIDTH}x{HEIGHT}", "format": "YUYV", "source": SOURCE, "frames": frames,
                       "rounds": rounds},
            "program_ms": round(float(np.median(client)) / 1e6, 3),
            "making_ms": round(float(np.median(made)) / 1e6, 3),
            "overhead_ms": round(overhead, 3), "overhead_p90_ms": round(float(np.percentile(over, 90)) / 1e6, 3),
            "targets": {"preload_overhead_ms": {"value": round(overhead, 3), "op": "<=", "limit": TARGET_MS,
                                                "pass": overhead <= TARGET_MS}}}


def format_report(doc: dict[str, Any]) -> str:
    """The plain-text report."""
    c = doc["config"]
    return (f"preload path, {c['size']} {c['format']}, {c['frames']} frames x {c['rounds']} rounds (medians):\n"
            f"  program's DQBUF+QBUF:            {doc['program_ms']:.3f} ms/frame\n"
            f"  server making the frame:         {doc['making_ms']:.3f} ms/frame (render, encode, the one fill)\n"
            f"  overhead of the preload path:    {doc['overhead_ms']:.3f} ms/frame, p90 {doc['overhead_p90_ms']:.3f} "
            f"(target <= {TARGET_MS} ms; per-frame differences in one run)")
