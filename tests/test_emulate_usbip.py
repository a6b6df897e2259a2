"""The firmware camera behind UVC: ``FirmwareProducer`` through pyusb, and ``rollcam emulate --usbip``."""

from __future__ import annotations

import itertools
import json
import socket
import subprocess
import sys

import pytest

pytest.importorskip("usb")

from interrupts import interrupt
from rollcam.firmware.camera import FirmwareCamera
from rollcam.host.sources import open_camera


def test_firmware_producer_programs_the_firmware_and_serves_its_frames():
    from rollcam.emu.uvc import FirmwareProducer, FrameProducer

    cam = FirmwareCamera("imx219", scene={"scene": "chart", "seed": 1})
    p = FirmwareProducer(cam)
    assert isinstance(p, FrameProducer)
    assert p.sizes()[0] == cam.size
    w, h = 640, 480
    interval = p.intervals_ns(w, h)[0]
    p.configure(w, h, interval)
    assert cam.streaming and cam.size == (w, h)
    first, second = p.frame(0), p.frame(1)
    assert (first.width, first.height) == (w, h) and second.sequence == first.sequence + 1
    assert second.timestamp_ns - first.timestamp_ns == pytest.approx(interval, abs=1)
    assert p.frame_due_ns(0) > first.timestamp_ns
    # UVC controls write the firmware's controls (and so its registers).
    timing = cam.spec.settings.timing  # UVC exposure is the spec's, whole lines of its exact line time
    assert p.set_control("exposure_ns", 5_000_000) == timing.line_offset_ns(cam.get_control("exposure"))
    assert p.set_control("gain", 400) == pytest.approx(400, abs=2)
    assert cam.state.gain == pytest.approx(4.0, rel=0.01)
    assert p.set_control("gain", 10**6) == p.control_range("gain").maximum  # clamped as the sensor does


def test_rollcam_emulate_usbip_streams_to_the_uvc_source():
    cmd = [sys.executable, "-m", "rollcam.host.cli", "emulate", "imx219", "--size", "640x480", "--scene", "flat",
           "--usbip", "127.0.0.1:0", "--usb-transfer", "bulk", "--usb-id", "046d:0825", "--json", "--duration", "120"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        info = json.loads(proc.stdout.readline())["usbip"]
        uri = (f"uvc:046d:0825?backend=usbip&usbip=127.0.0.1:{info['port']}&busid={info['busids'][0]}"
               "&size=640x480&sensor=imx219&frames=3")
        with open_camera(uri) as src:
            frames = list(src)
        assert len(frames) == 3 and frames[0].data.shape == (480, 640, 3)
        assert all(b.timestamp_ns > a.timestamp_ns for a, b in itertools.pairwise(frames))
        _out, err = interrupt(proc, timeout_s=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.1", info["port"]), timeout=2).close()


def test_two_transports_rendering_at_once_get_their_own_frames():
    import threading

    from rollcam.firmware.camera import FramePlan

    cam = FirmwareCamera("imx219", size=(640, 480), scene={"scene": "street", "seed": 2, "speed": "fast"})
    cam.stream_on()
    sched = cam.current_schedule()
    wrong: list[int] = []

    def run(first: int) -> None:
        for seq in range(first, first + 15):
            frame = cam.render(FramePlan(seq, sched))
            if frame.timestamp_ns != sched.start_ns(seq) or frame.sequence != seq:
                wrong.append(seq)

    threads = [threading.Thread(target=run, args=(k,)) for k in (0, 100_000)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert wrong == []


def test_a_timing_change_during_a_uvc_only_stream_moves_only_later_frames():
    from rollcam.emu.uvc import FirmwareProducer

    cam = FirmwareCamera("imx219", scene={"scene": "flat"})
    p = FirmwareProducer(cam)
    p.configure(640, 480, p.intervals_ns(640, 480)[0])
    for i in range(101):
        p.frame_due_ns(i)
    p.frame(100)
    due_101 = p.frame_due_ns(101)
    period = cam.frame_interval_ns
    cam.set_control("vblank", cam.get_control("vblank") * 3)  # a longer frame, e.g. over the serial line
    assert cam.frame_interval_ns > period
    # Frame 101 starts one (new) period after frame 100, not three periods times 101 after the commit.
    assert abs(p.frame_due_ns(101) - due_101) < cam.frame_interval_ns


def test_late_frames_are_skipped_in_closed_form():
    cam = FirmwareCamera("imx219", size=(640, 480), scene={"scene": "flat"}, clock=lambda: 0)
    cam.stream_on()
    sched = cam.current_schedule()
    ten_days = 10 * 86_400 * 10**9
    plan = cam.plan_next(now_ns=ten_days)
    assert sched.frame_due_ns(plan.seq) >= ten_days > sched.frame_due_ns(plan.seq - 1)
    assert cam.stats.skipped == plan.seq
