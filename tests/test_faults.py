"""The one fault description (rollcam.common.faults) and what it does on the V4L2 API, the emu: source and the CLI.

Each fault reaches the client as the real failure would (the errno, the ERROR flag, the sequence gap), and the
client's own count of failures equals the injected count for a fixed seed. The other transports:
test_faults_transports.py.
"""

from __future__ import annotations

import errno
import json
import subprocess
import sys

import numpy as np
import pytest
from rollcam.common.errors import ConfigError, SourceError
from rollcam.common.faults import FAULT_COUNTERS, S64, U32, FaultInjector, FaultPlan, draw
from rollcam.emu.v4l2 import Device, V4L2Error
from rollcam.emu.v4l2 import functions as fn
from rollcam.host.sources import open_camera


def dev(faults: str, **kw) -> Device:
    kw.setdefault("realtime", False)
    return Device.open("imx219", scene={"scene": "flat"}, size=(640, 480), faults=faults, **kw)


def errno_of(call, *args, **kw) -> int:
    with pytest.raises(V4L2Error) as info:
        call(*args, **kw)
    return info.value.errno


# ------------------------------------------------------------------------------------------------ the plan
def test_plan_text_round_trips_and_defaults_follow_vivid():
    p = FaultPlan.parse("drop=2%, error=1.5 ,stall=0.5%,disconnect=300,qbuf=EIO@3,reqbufs,seqwrap,tswrap,"
                        "delay_ms=9,seed=7")
    assert p.rate("drop") == 2.0 and p.rate("error") == 1.5 and p.rate("babble") == 0.0
    assert p.disconnect == 300 and p.seed == 7
    assert p.request_error("qbuf", 3) == errno.EIO and p.request_error("qbuf", 1) is None
    assert p.request_error("reqbufs", 1) == errno.EINVAL  # vivid's button: the next call, -EINVAL
    assert p.sequence(0) == 0xFFFFFF80 and p.sequence(128) == 0  # vivid's seq_wrap start
    assert p.timestamp_ns(5, 5) == S64 - 16 * 10**9 and p.timestamp_ns(16 * 10**9 + 5, 5) == -S64  # 16 s in
    assert FaultPlan.parse(p.to_text()) == p
    assert FaultPlan.of(None) == FaultPlan() and not FaultPlan() and str(FaultPlan()) == "none"
    assert FaultPlan.of(p) is p and FaultPlan.of("drop=2") == FaultPlan.parse("drop=2%")


@pytest.mark.parametrize("text", ["drop=101%", "drop=-1", "drop=nan", "drop", "frobnicate=1", "qbuf=EFOO",
                                  "qbuf=EIO@0", "disconnect=x", "seed=-1", "drop=1,drop=2", "delay_ms=1e9",
                                  "seqwrap=0"])
def test_bad_plans_are_refused_naming_the_value(text):
    with pytest.raises(ConfigError) as info:
        FaultPlan.parse(text, "--faults")
    assert "--faults" in str(info.value) and repr(text) in str(info.value)


def test_decisions_are_a_pure_function_of_seed_kind_and_index():
    p = FaultPlan.parse("drop=5%,error=5%,seed=11")
    hits = [i for i in range(20_000) if p.fires("drop", i)]
    assert hits == [i for i in range(20_000) if FaultPlan.parse("seed=11,drop=5").fires("drop", i)]
    assert 800 < len(hits) < 1200  # 5 % of 20,000
    other = [i for i in range(20_000) if p.fires("error", i)]
    assert len(set(hits) & set(other)) < 150  # the kinds are drawn independently (expected ~50)
    assert hits != [i for i in range(20_000) if FaultPlan.parse("drop=5%,seed=12").fires("drop", i)]
    assert draw(11, "drop", 3) == draw(11, "drop", 3) != draw(11, "drop", 4)
    inj = FaultInjector(p)
    assert sum(inj.hit("drop", i) for i in range(20_000)) == len(hits) == inj.stats.dropped
    assert set(inj.stats.to_json()) == set(FAULT_COUNTERS)


# ------------------------------------------------------------------------------------------------ V4L2
def _stream(faults: str, frames: int = 24):
    with dev(faults) as d:
        bufs = list(d.stream(buffers=4, frames=frames))
        return bufs, d.driver.fault_stats


def test_v4l2_drops_are_sequence_gaps_and_errors_are_flags_matching_the_injected_counts():
    bufs, stats = _stream("drop=25%,error=20%,seed=5")
    seqs = [b.sequence for b in bufs]
    missing = sum(int(g) - 1 for g in np.diff([-1, *seqs]))
    assert missing == stats.dropped > 0  # the client counts the gaps, the driver the drops
    assert sum(b.error for b in bufs) == stats.errors > 0
    plan = FaultPlan.parse("drop=25%,error=20%,seed=5")
    assert [i for i in range(seqs[-1] + 1) if plan.fires("drop", i)] == sorted(set(range(seqs[-1] + 1)) - set(seqs))
    again, _ = _stream("drop=25%,error=20%,seed=5")
    assert [(b.sequence, b.error) for b in again] == [(b.sequence, b.error) for b in bufs]  # reproducible
    other, _ = _stream("drop=25%,error=20%,seed=6")
    assert [b.sequence for b in other] != seqs


def test_v4l2_one_shot_request_errors_carry_their_errno():
    with dev("reqbufs,qbuf=EIO@2,streamon=ENOSPC,s_fmt=EBUSY") as d:
        h = d.driver
        assert errno_of(d.set_format, 640, 480, "YUYV") == errno.EBUSY
        d.set_format(640, 480, "YUYV")  # one shot: the next call goes through
        assert errno_of(fn.request_buffers, h, 4) == errno.EINVAL
        n = fn.request_buffers(h, 4)
        fn.queue_buffer(h, 0)
        assert errno_of(fn.queue_buffer, h, 1) == errno.EIO
        for i in range(1, n):
            fn.queue_buffer(h, i)
        assert errno_of(fn.stream_on, h) == errno.ENOSPC
        fn.stream_on(h)
        buf, _ = fn.dequeue_buffer(h)
        assert buf.sequence == 0 and h.fault_stats.request_errors == 4


def test_v4l2_disconnect_gives_enodev_until_the_device_is_closed():
    d = dev("disconnect=3")
    h = d.driver
    n = fn.request_buffers(h, 4)
    for i in range(n):
        fn.queue_buffer(h, i)
    fn.stream_on(h)
    got = []
    for _ in range(3):
        buf, _ = fn.dequeue_buffer(h)
        got.append(buf.sequence)
        fn.queue_buffer(h, buf.index)
    assert got == [0, 1, 2]
    assert errno_of(fn.dequeue_buffer, h) == errno.ENODEV
    assert errno_of(fn.querycap, h) == errno.ENODEV and errno_of(fn.queue_buffer, h, 0) == errno.ENODEV
    assert h.fault_stats.disconnects == 1
    d.close()  # vivid: connected again once every handle is closed
    assert fn.querycap(h).driver == "rollcam"
    assert len(list(Device(h).stream(frames=5))) == 5  # and it does not unplug twice


def test_v4l2_sequence_and_timestamp_wrap():
    with dev("seqwrap=3,tswrap=1", fps=15) as d:
        bufs = list(d.stream(frames=17))
        timing = d.driver.camera.state.timing
    assert [b.sequence for b in bufs[:6]] == [U32 - 3, U32 - 2, U32 - 1, 0, 1, 2]
    ts = [b.timestamp_ns for b in bufs]
    assert ts[0] == S64 - 10**9 and ts[-1] < 0  # 15 fps: the signed 64-bit ns wrap comes 1 s in, at frame 16
    for k in range(1, len(ts)):  # modulo 2**64 no time is lost at the wrap
        assert (ts[k] - ts[k - 1]) % (2 * S64) == timing.frame_start_ns(k) - timing.frame_start_ns(k - 1)


def test_v4l2_realtime_faults_follow_the_device_frame_number():
    with dev("drop=30%,seed=2", realtime=True, bands=2) as d:
        bufs = list(d.stream(buffers=6, frames=20, timeout_s=10))
        stats, driver_stats, seq0 = d.driver.fault_stats, d.driver.stats, d.driver.seq0
        skipped = d.driver.camera.stats.skipped  # frames a loaded machine's pump fell behind on
    seqs = [b.sequence for b in bufs]
    plan = FaultPlan.parse("drop=30%,seed=2")
    injected = {i for i in range(seqs[-1] + 1) if plan.fires("drop", seq0 + i)}  # by device frame number
    missing = set(range(seqs[-1] + 1)) - set(seqs)
    assert injected <= missing and injected  # every injected drop is a gap; the others were never made in time
    assert len(missing - injected) <= driver_stats.dropped_no_buffer + skipped and len(injected) <= stats.dropped


# ------------------------------------------------------------------------------------------------ emu: URI
def test_emu_uri_takes_the_same_plan():
    src = open_camera("emu:imx219?size=640x480&scene=flat&faults=drop=30,error=30,disconnect=6,seed=3")
    frames = [src.read() for _ in range(6)]
    with pytest.raises(SourceError, match="disconnected"):
        src.read()
    seqs = [f.sequence for f in frames]
    assert seqs[-1] + 1 - 6 == src.fault_stats.dropped > 0
    assert sum(bool(f.meta.get("error")) for f in frames) == src.fault_stats.errors > 0
    src.close()
    with pytest.raises(SourceError, match=r"drop=300"):
        open_camera("emu:imx219?faults=drop=300")


def test_fixtures_pass_the_plan_through(rollcam_camera, rollcam_v4l2_device):
    src = rollcam_camera("imx219", scene="flat", size="640x480", faults="drop=50%,seed=1")
    seqs = [src.read().sequence for _ in range(4)]
    assert seqs[-1] + 1 - 4 == src.fault_stats.dropped > 0
    d = rollcam_v4l2_device("imx219", scene={"scene": "flat"}, size=(640, 480), realtime=False,
                            faults="error=100%")
    assert all(b.error for b in d.stream(frames=2)) and d.driver.fault_stats.errors == 2


# ------------------------------------------------------------------------------------------------ CLI
def test_emulate_refuses_a_bad_plan_and_reports_a_good_one():
    cmd = [sys.executable, "-m", "rollcam.host.cli", "emulate", "imx219", "--size", "640x480", "--scene", "flat"]
    bad = subprocess.run([*cmd, "--faults", "drop=2%,wobble=1"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "wobble" in bad.stderr and "--faults" in bad.stderr
    good = subprocess.run([*cmd, "--faults", "drop=2%,seed=7", "--http", "127.0.0.1:0", "--duration", "0",
                           "--json"], capture_output=True, text=True, timeout=120)
    assert good.returncode == 0, good.stderr
    assert json.loads(good.stdout.splitlines()[0])["faults"] == "drop=2%,seed=7"


def test_whole_number_faults_name_their_range_and_draws_keep_their_stream():
    """The plan's whole numbers go through common.values.bounded and its draws through common.mixing: the same
    messages and the same 64-bit stream as the plan's own parser and mixer gave (values pinned from those)."""
    for text, span in [("seqskip_by=0", "1..4294967295"), ("seed=x", "0..18446744073709551615"),
                       ("delay_ms=1e9", "0..60000"), ("qbuf=EIO@0", "1..4294967296")]:
        with pytest.raises(ConfigError) as info:
            FaultPlan.parse(text, "--faults")
        assert str(info.value) == f"--faults: fault {text!r} in {text!r}: expected a whole number in {span}"
    assert [draw(0, "error", i) for i in range(3)] == [17983244471914978917, 6854649170381038390,
                                                       3617272679030404135]
