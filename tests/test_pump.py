"""The real-time pump: bands in readout order, never before their device time; several sinks; clean stop."""

from __future__ import annotations

import threading

from rollcam.emu.pump import FramePump
from rollcam.firmware.camera import FirmwareCamera


class Recorder:
    """A sink that records (seq, band, clock at the call, band due time)."""

    def __init__(self, camera: FirmwareCamera, frames: int) -> None:
        self.camera, self.frames = camera, frames
        self.bands: list[tuple[int, int, int, int]] = []
        self.done: list[int] = []
        self.enough = threading.Event()

    def on_band(self, frame, plan, band, n_bands) -> None:
        self.bands.append((plan.seq, band, self.camera.clock_ns(), plan.schedule.band_due_ns(plan.seq, band, n_bands)))

    def on_frame(self, frame, plan) -> None:
        assert frame.sequence == plan.seq
        self.done.append(plan.seq)
        if len(self.done) >= self.frames:
            self.enough.set()


def test_bands_arrive_in_order_and_never_early_to_every_sink():
    cam = FirmwareCamera("imx219", scene={"scene": "flat"}, size=(640, 480))
    a, b = Recorder(cam, 4), Recorder(cam, 4)
    with FramePump(cam, bands=6) as pump:
        pump.add_sink(a)
        pump.add_sink(b)
        cam.stream_on()
        assert a.enough.wait(20) and b.enough.wait(20)
        pump.remove_sink(b)
    assert pump.error is None
    for seq, band, at, due in a.bands:
        assert at >= due, (seq, band)
    firsts = [i for i, r in enumerate(a.bands) if r[1] == 0]
    for i in firsts[:-1]:
        assert [r[1] for r in a.bands[i:i + 6]] == list(range(6))
    assert a.done == sorted(a.done)


def test_pump_idles_until_streaming_and_stops_cleanly():
    cam = FirmwareCamera("imx219", scene={"scene": "flat"}, size=(640, 480))
    rec = Recorder(cam, 1)
    pump = FramePump(cam, bands=2)
    pump.add_sink(rec)
    pump.start()
    assert not rec.enough.wait(0.3) and rec.bands == []  # not streaming: nothing made
    cam.stream_on()
    assert rec.enough.wait(20)
    pump.close()
    pump.close()
    assert not pump._worker.alive and pump.closed


def test_realtime_priority_is_used_or_refusal_reported():
    cam = FirmwareCamera("imx219", scene={"scene": "flat"}, size=(640, 480))
    rec = Recorder(cam, 2)
    with FramePump(cam, bands=2, rt_priority=1) as pump:
        pump.add_sink(rec)
        cam.stream_on()
        assert rec.enough.wait(20)
    assert pump.error is None
    assert pump.stats.rt == "SCHED_FIFO 1" or str(pump.stats.rt).startswith("refused")
    for _seq, _band, at, due in rec.bands:
        assert at >= due


class FrameLog(Recorder):
    """Records each delivered frame's (sequence, exposure start, exposure, due)."""

    def __init__(self, camera: FirmwareCamera, frames: int) -> None:
        super().__init__(camera, frames)
        self.frames_seen: list[tuple[int, int, int]] = []

    def on_frame(self, frame, plan) -> None:
        self.frames_seen.append((frame.sequence, frame.timestamp_ns, frame.exposure_ns))
        super().on_frame(frame, plan)


def test_frames_made_ahead_follow_a_change_from_the_first_frame_exposed_after_it():
    """Render-ahead keeps frames made before they are due; a control change throws away the ones that had not
    started exposing, so every frame exposed after the change has the new exposure and none before it."""
    cam = FirmwareCamera("imx219", scene={"scene": "flat"}, size=(640, 480))
    log = FrameLog(cam, 14)
    with FramePump(cam, bands=2, ahead=3) as pump:
        pump.add_sink(log)
        cam.stream_on()
        while len(log.done) < 5:
            assert not log.enough.wait(0.02) or len(log.done) >= 5
        old = cam.spec.settings.exposure_ns
        cam.set_control("exposure", 100)
        changed_ns = cam.spec_changed_ns
        new = cam.spec.settings.exposure_ns
        assert log.enough.wait(30)
    assert pump.error is None and new != old
    seqs = [s for s, _, _ in log.frames_seen]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    for seq, start_ns, exposure_ns in log.frames_seen:
        assert exposure_ns == (new if start_ns >= changed_ns else old), (seq, start_ns, changed_ns)
    assert any(start >= changed_ns for _, start, _ in log.frames_seen)
    assert pump.stats.remade >= 1  # frames had been made ahead with the old exposure, and were made again


def test_a_skipped_frames_insensor_results_ride_on_the_next_frame_handed_out():
    """A consumer that stalls makes the pump skip frames it had made ahead; the in-sensor results those frames
    carried are not lost: every result of a frame before the last one handed out reaches the sink, once, in
    order."""
    import time

    from rollcam.firmware.spec import CameraSpec

    cam = FirmwareCamera(CameraSpec.from_options("letsroll", {"size": "320x180", "pedestrians": "4", "fps": "10",
                                                              "insensor": "personnet-raw"}))
    got: list[tuple[int, list[int]]] = []
    enough = threading.Event()

    class Stalling:
        def on_band(self, frame, plan, band, n_bands) -> None:
            pass

        def on_frame(self, frame, plan) -> None:
            got.append((frame.sequence, [r.seq for r in frame.insensor or ()]))
            if len(got) % 4 == 3:
                time.sleep(0.55)  # 5.5 frame periods: the frames made ahead are all late by the next hand-out
            if len(got) >= 12:
                enough.set()

    with FramePump(cam, bands=2) as pump:
        pump.add_sink(Stalling())
        cam.stream_on()
        assert enough.wait(60)
        cam.stream_off()
    assert pump.error is None and pump.stats.late_skipped > 0
    carried = [s for _, seqs in got for s in seqs]
    assert carried == sorted(set(carried))
    last = got[-1][0]
    assert {r.seq for r in cam.insensor.recent(1 << 62) if r.seq < last} <= set(carried)
