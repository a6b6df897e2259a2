"""Lab faults (issue 41): frame-counter rewrite/freeze/skip, grey/black/frozen images and sensor register resets,
each seen through the client that would see it (the V4L2 API, v4l2-ctl under ``rollcam run``, pyserial on the
pty, a raw HTTP multipart reader, the ``emu:`` source) and compared with the injected counts."""

from __future__ import annotations

import hashlib
import json
import re

import cv2
import numpy as np
import pytest
from programs import need, python_under
from programs import run_under as run
from rollcam.common.errors import ConfigError
from rollcam.common.faults import COUNTER_FAULTS, IMAGE_FAULTS, U32, FaultInjector, FaultPlan
from rollcam.emu.serial_pty import PtySerialServer
from rollcam.emu.v4l2 import Device, EmuDriver, raw
from rollcam.firmware.camera import FirmwareCamera
from rollcam.host.servers.devnodes import serving
from rollcam.host.sources import open_camera
from rollcam.sim.codecs import codec

COUNTERS = "seqrewrite=8,seqrewrite_to=1000,seqfreeze=15,seqskip=15,seqskip_by=4,seed=3"


def dev(faults: str, **kw) -> Device:
    kw.setdefault("realtime", False)
    kw.setdefault("size", (160, 120))
    return Device.open("imx219", scene={"scene": "street"}, faults=faults, **kw)


def expected_counters(plan: FaultPlan, frames: int) -> tuple[list[int], dict[str, int]]:
    """What the device's counter shows for frames 0..frames-1, by hand from the plan's draws, and the faults."""
    c = (U32 - plan.seqwrap) % U32 if plan.seqwrap else 0
    seqs, hits = [c], dict.fromkeys(COUNTER_FAULTS, 0)
    for n in range(1, frames):
        kind = next((k for k in COUNTER_FAULTS if plan.fires(k, n)), None)
        c = {"seqrewrite": plan.seqrewrite_to, "seqfreeze": c}.get(kind, c + 1 + (plan.seqskip_by if kind else 0))
        seqs.append(c % U32)
        hits[kind or "seqrewrite"] += kind is not None
    return seqs, hits


# ------------------------------------------------------------------------------------------------ the plan
def test_lab_fault_text_round_trips_and_bad_values_are_named():
    p = FaultPlan.parse(f"{COUNTERS},grey=1%,black=2,frozen=3,regreset=0.5,burst=1,burst_px=9,stuck=4,dead=5,"
                        "hot=6,hot_dn_per_ms=7,soiling=2")
    assert (p.seqrewrite_to, p.seqskip_by, p.burst_px, p.hot_dn_per_ms) == (1000, 4, 9, 7)
    assert (p.defect("stuck"), p.defect("dead"), p.defect("hot"), p.defect("soiling")) == (4, 5, 6, 2)
    assert p.rate("frozen") == 3 and p.rate("regreset") == 0.5 and FaultPlan.parse(p.to_text()) == p
    assert FaultPlan.parse("stuck=1") and not FaultPlan.parse("stuck=0,seqskip_by=3").rates
    for bad in ("seqskip_by=0", "seqrewrite_to=4294967296", "stuck=-1", "soiling", "grey=101", "hot=many",
                "burst_px=0"):
        with pytest.raises(ConfigError) as info:
            FaultPlan.parse(bad, "--faults")
        assert repr(bad) in str(info.value) and "--faults" in str(info.value)


def test_counter_faults_follow_the_seeded_draws_and_count_as_they_are_delivered():
    plan = FaultPlan.parse(COUNTERS)
    seqs, hits = expected_counters(plan, 400)
    assert [plan.sequence(n) for n in range(0, 400, 37)] == seqs[::37]
    inj = FaultInjector(plan)
    assert [inj.sequence(n) for n in range(400)] == seqs
    assert (inj.stats.seq_rewrites, inj.stats.seq_freezes, inj.stats.seq_skips) == tuple(hits.values())
    assert all(hits.values()) and 1000 in seqs
    wrapped = FaultPlan.parse(f"{COUNTERS},seqwrap=5")
    assert [wrapped.sequence(n) for n in range(40)] == expected_counters(wrapped, 40)[0]


# ------------------------------------------------------------------------------------------------ V4L2
def test_v4l2_sequence_shows_the_counter_faults_matching_the_counts():
    with dev(COUNTERS) as d:
        bufs = list(d.stream(buffers=4, frames=60))
        stats = d.driver.fault_stats
    seqs, hits = expected_counters(FaultPlan.parse(COUNTERS), 60)
    assert [b.sequence for b in bufs] == seqs
    assert (stats.seq_rewrites, stats.seq_freezes, stats.seq_skips) == tuple(hits.values())
    assert stats.seq_freezes and stats.seq_skips and stats.seq_rewrites


@pytest.mark.parametrize("fourcc", ["YUYV", "RG10"])
def test_v4l2_grey_black_and_frozen_frames_in_the_buffers(fourcc):
    faults = "grey=20,black=20,frozen=20,seed=4"
    with dev(faults, pixel_format=fourcc) as d:
        bufs = [(b.sequence, b.data.tobytes()) for b in d.stream(buffers=4, frames=30)]
        stats, camera = d.driver.fault_stats, d.driver.camera
    plan = FaultPlan.parse(faults)
    c = codec(fourcc)
    black_dn = camera.sensor.noise.black_level_dn / (1 << (camera.sensor.bit_depth - 10))
    if c.raw:  # samples from the sensor's black level (scaled to 10 bits) to full scale
        grey = c.encode(np.full((120, 160), round(black_dn + 0.5 * (1023 - black_dn)), np.uint16)).tobytes()
        black = c.encode(np.full((120, 160), round(black_dn), np.uint16)).tobytes()
    else:
        grey = c.encode(np.full((120, 160, 3), 128, np.uint8)).tobytes()
        black = c.encode(np.zeros((120, 160, 3), np.uint8)).tobytes()
    seen = dict.fromkeys(IMAGE_FAULTS, 0)
    for k, (seq, data) in enumerate(bufs):
        kind = plan.first_of(IMAGE_FAULTS if k else IMAGE_FAULTS[:2], seq)
        if kind == "grey":
            assert data == grey
        elif kind == "black":
            assert data == black
        elif kind == "frozen":
            assert data == bufs[k - 1][1]
        else:
            assert data not in (grey, black, bufs[k - 1][1])  # the street, a new frame
        seen[kind or "grey"] += kind is not None
    assert (stats.grey_frames, stats.black_frames, stats.frozen_frames) == tuple(seen.values())
    assert all(seen.values())


@pytest.mark.parametrize("fourcc", ["YUYV", "RG10"])
def test_no_lab_fault_keeps_every_frame_byte_identical(fourcc):
    """A plan with only parameters, or rates of 0, changes nothing: the same bytes as a device without a plan
    (on a fixed clock, so two devices make the same frames)."""

    def digest(faults: str | None) -> str:
        with dev(faults, pixel_format=fourcc, clock=lambda: 0) as d:
            h = hashlib.sha256()
            for b in d.stream(frames=4):
                h.update(b.data.tobytes() + b.sequence.to_bytes(4, "little"))
            return h.hexdigest()

    assert digest(None) == digest("seqskip_by=3,burst_px=9,seed=4") == digest("grey=0,seqfreeze=0,regreset=0")


def test_register_reset_returns_the_controls_mid_stream_on_v4l2_and_serial():
    serial = pytest.importorskip("serial")
    faults = "regreset=10,seed=2"
    plan = FaultPlan.parse(faults)
    first = next(n for n in range(100) if plan.fires("regreset", n))
    assert 2 <= first < 30  # mid-stream, for this seed
    camera = FirmwareCamera("imx219", size=(160, 120), scene={"scene": "flat"})
    driver = EmuDriver(camera, realtime=False, faults=faults)
    with PtySerialServer(camera) as srv, serial.Serial(srv.path, timeout=5) as port, Device(driver) as d:
        default = d.controls["exposure"].value
        port.write(b"CTRL exposure 100\n")
        assert port.readline() == b"OK 100\r\n"
        assert d.controls["exposure"].value == 100
        exposures = [b.sequence for b in d.stream(frames=first)]  # the frames before the reset
        assert d.controls["exposure"].value == 100 and len(exposures) == first
        list(d.stream(frames=1))  # frame ``first``: the registers reset
        assert d.controls["exposure"].value == default
        port.write(b"CTRL? exposure\n")
        assert port.readline() == f"{default}\r\n".encode()
        port.write(b"STATS?\n")
        assert f"register_resets={driver.fault_stats.register_resets}" in port.readline().decode()
    assert driver.fault_stats.register_resets == camera.stats.register_resets >= 1


# ------------------------------------------------------------------------------------------------ rollcam run
def test_v4l2_ctl_under_rollcam_run_sees_counter_and_image_faults_and_a_register_reset(tmp_path):
    need("v4l2-ctl")
    faults = "seqfreeze=20,seqskip=20,seqskip_by=2,regreset=10,grey=15,frozen=15,seed=2"
    plan = FaultPlan.parse(faults)
    source = f"emu:imx219?size=160x120&format=YUYV&scene=flat&faults={faults}"
    with serving([("/dev/video0", source)], realtime=False) as s:
        driver = s.nodes["/dev/video0"].driver
        default = driver.ctrl_defaults["exposure"]
        out = run(s, "v4l2-ctl", "-d", "/dev/video0", "--set-ctrl=exposure=100", "--verbose", "--stream-mmap",
                  "--stream-count=30", f"--stream-to={tmp_path / 'a.yuyv'}")
        text = out.stdout + out.stderr
        seqs = [int(m) for m in re.findall(r"seq:\s*(\d+)", text)]
        got = run(s, "v4l2-ctl", "-d", "/dev/video0", "--get-ctrl=exposure").stdout
        stats = driver.fault_stats
    want, hits = expected_counters(plan, 30)
    assert seqs == want
    frames = np.fromfile(tmp_path / "a.yuyv", np.uint8).reshape(30, -1)
    grey = codec("YUYV").encode(np.full((120, 160, 3), 128, np.uint8)).reshape(-1)
    kinds = [plan.first_of(("grey", "frozen") if n else ("grey",), n) for n in range(30)]
    for n, kind in enumerate(kinds):
        same = (frames[n] == frames[n - 1]).all() if n else False
        assert (frames[n] == grey).all() == (kind == "grey" or (kind == "frozen" and (frames[n - 1] == grey).all()))
        assert same if kind == "frozen" else (kind or not same)  # noise moves a clean frame: never a repeat
    frozen = [n for n, k in enumerate(kinds) if k == "frozen"]
    assert (stats.grey_frames, stats.frozen_frames) == (kinds.count("grey"), len(frozen))
    assert (stats.seq_freezes, stats.seq_skips) == (hits["seqfreeze"], hits["seqskip"]) and stats.seq_freezes
    assert f"exposure: {default}" in got and default != 100
    assert stats.register_resets == sum(plan.fires("regreset", n) for n in range(30)) >= 1


# ------------------------------------------------------------------------------------------------ emu: and HTTP
def test_emu_source_frames_carry_counter_and_image_faults():
    faults = "seqskip=100,seqskip_by=9,grey=30,seed=1"
    src = open_camera(f"emu:imx219?size=160x120&scene=street&faults={faults}")
    frames = [src.read() for _ in range(12)]
    plan = FaultPlan.parse(faults)
    assert [f.sequence for f in frames] == [10 * n for n in range(12)]
    greys = [n for n in range(12) if plan.fires("grey", n)]
    assert [n for n, f in enumerate(frames) if f.meta.get("image_fault") == "grey"] == greys
    assert all(np.all(frames[n].data == 128) and frames[n].objects == () for n in greys) and greys
    assert all(frames[n].objects for n in range(12) if n not in greys)  # the street's truth on the others
    assert src.fault_stats.seq_skips == 11 and src.fault_stats.grey_frames == len(greys)
    src.close()


def test_http_parts_carry_the_faulted_counter_and_grey_images(rollcam_http_camera):
    from test_faults_transports import _read_parts

    srv = rollcam_http_camera("imx219", scene={"scene": "street"}, size=(160, 120),
                              faults="seqskip=100,seqskip_by=4,grey=100")
    parts, _ = _read_parts(srv.url, limit=6)
    seqs = [int(h["X-Sequence"]) for h, _, _ in parts]
    assert len(parts) == 6 and all(s % 5 == 0 for s in seqs) and seqs == sorted(seqs)
    for _, body, _ in parts:
        img = cv2.imdecode(np.frombuffer(body, np.uint8), cv2.IMREAD_COLOR)
        assert img.shape == (120, 160, 3) and np.abs(img.astype(int) - 128).max() <= 2  # JPEG of mid-grey
    st = srv.fault_stats  # counted on every part made (a part made before the client came too); frame 0 starts
    assert st.seq_skips >= sum(s > 0 for s in seqs) and st.grey_frames >= 6


# ------------------------------------------------------------------------------------------------ sensor defects
DEFECTS = "stuck=40,dead=40,hot=40,soiling=3,burst=50,burst_px=100,seed=9"


def _raw_frames(faults: str | None, n: int = 3, **options: str) -> tuple[list, object]:
    opts = "&".join(f"{k}={v}" for k, v in {"size": "320x240", "scene": "street", "format": "RG10", **options}.items())
    src = open_camera(f"emu:imx219?{opts}" + (f"&faults={faults}" if faults else ""))
    frames = [src.read() for _ in range(n)]
    src.close()
    return frames, src


def test_sensor_defects_change_only_the_pixels_the_truth_names():
    clean, _ = _raw_frames(None)
    faulty, src = _raw_frames(DEFECTS)
    c = codec("RG10")
    bursts = 0
    for a, b in zip(clean, faulty, strict=True):
        truth = b.meta["defects"]
        assert "defects" in b.to_json() and len(truth["stuck"]) == len(truth["dead"]) == len(truth["hot"]) == 40
        sa, sb = c.decode(a.data, 320, 240), c.decode(b.data, 320, 240)
        named = np.zeros(sa.shape, bool)
        for x, y, value in truth["stuck"]:
            assert sb[y, x] == value
            named[y, x] = True
        for x, y in truth["dead"]:
            assert sb[y, x] == 0
            named[y, x] = True
        yy, xx = np.mgrid[0:240, 0:320]
        near = np.zeros(sa.shape, bool)
        for cx, cy, r, _ in truth["soiling"]:
            near |= (xx - cx) ** 2 + (yy - cy) ** 2 < (3.5 * r) ** 2  # the blob and its blur's reach
        for x, y in truth["hot"]:
            if not near[y, x]:  # 40 DN/ms of dark current on top of the light
                assert int(sb[y, x]) >= min(int(sa[y, x]) + 40 * b.exposure_ns // 10**6, 1023) - 1
            named[y, x] = True
        named |= near
        if "burst" in truth:
            bursts += 1
            start = truth["burst"]["y"] * 320 + truth["burst"]["x"]
            named.reshape(-1)[start:start + truth["burst"]["length"]] = True
        changed = sa != sb
        assert not (changed & ~named).any()  # nothing else moved: the same noise, the same scene
        assert changed.sum() > 100
        soiled = [(int(cy), int(cx)) for cx, cy, _, _ in truth["soiling"] if 0 <= cx < 320 and 0 <= cy < 240]
        assert all(int(sb[p]) <= int(sa[p]) + 64 for p in soiled)  # attenuated (not brightened) under a blob
    assert bursts == src.fault_stats.bursts >= 1
    plan = FaultPlan.parse(DEFECTS)
    assert [("burst" in f.meta["defects"]) for f in faulty] == [plan.fires("burst", n) for n in range(3)]


def test_hot_pixels_scale_with_exposure_and_raw_and_processed_frames_agree():
    short, _ = _raw_frames("hot=30,seed=2", 1, exposure_us="2000", scene="flat", level="0.05")
    long, _ = _raw_frames("hot=30,seed=2", 1, exposure_us="8000", scene="flat", level="0.05")
    c = codec("RG10")
    s, lo = c.decode(short[0].data, 320, 240), c.decode(long[0].data, 320, 240)
    hot = short[0].meta["defects"]["hot"]
    assert hot == long[0].meta["defects"]["hot"]  # fixed on the array
    rise = np.mean([int(lo[y, x]) - int(s[y, x]) for x, y in hot])
    assert 40 * 6 * 0.8 < rise < 40 * 6 * 1.2 + 40  # 40 DN/ms more over 6 ms more (the scene adds a little)
    raw = open_camera("emu:imx219?size=320x240&scene=street&format=RG10&faults=stuck=20,dead=20,soiling=2")
    bgr = open_camera("emu:imx219?size=320x240&scene=street&format=BGR3&physics=1&faults=stuck=20,dead=20,soiling=2")
    r, b = raw.read(), bgr.read()
    assert r.meta["defects"] == b.meta["defects"]
    pipe = bgr.camera.pipeline
    assert np.array_equal(pipe.encode(c.decode(r.data, 320, 240)), b.data)  # the ISP picture of the same samples
    raw.close()
    bgr.close()


def test_v4l2_ctl_under_rollcam_run_streams_the_defective_pixels(tmp_path):
    need("v4l2-ctl")
    faults = "stuck=30,dead=30,seed=5"
    truth = open_camera(f"emu:imx219?size=320x240&scene=street&format=RG10&faults={faults}").read().meta["defects"]
    with serving([("/dev/video0", f"emu:imx219?size=320x240&scene=street&format=RG10&faults={faults}")],
                 realtime=False) as s:
        run(s, "v4l2-ctl", "-d", "/dev/video0", "--stream-mmap", "--stream-count=3",
            f"--stream-to={tmp_path / 'a.raw'}")
    frames = np.fromfile(tmp_path / "a.raw", "<u2").reshape(3, 240, 320)
    for f in frames:
        assert all(f[y, x] == 0 for x, y in truth["dead"]) and all(f[y, x] == v for x, y, v in truth["stuck"])
    assert (frames == 0).sum(axis=(1, 2)).min() >= 30


def test_bad_lab_faults_are_one_line_cli_errors(capsys, tmp_path):
    from rollcam.host.cli import main

    assert main(["emulate", "imx219", "--faults", "seqskip=5,seqskip_by=0", "--http", "127.0.0.1:0",
                 "--duration", "0"]) == 2
    assert main(["capture", "emu:imx219?faults=stuck=many", "--frames", "1", "--out", str(tmp_path / "a")]) == 2
    assert main(["capture", "emu:imx219?physics=0&faults=dead=3", "--frames", "1", "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 3 and all(line.startswith("rollcam: error: ") for line in err)
    assert "'seqskip_by=0'" in err[0] and "'stuck=many'" in err[1]
    assert "sensor defects (dead=3) need the sensor model (physics on)" in err[2]


# ------------------------------------------------------------------------------------------------ UVC
def test_pyusb_reads_grey_black_and_frozen_frames_as_counted():
    from rollcam.emu.uvc import PayloadParser
    from test_faults_transports import YUYV_64x48, _commit, _pyusb

    faults = "grey=20,black=20,frozen=20,seed=6"
    _producer, fn, _backend, dev = _pyusb(faults)
    probe = _commit(dev)
    dev.set_interface_altsetting(1, 4)
    parser = PayloadParser(probe.dwClockFrequency, YUYV_64x48)
    frames = []
    while len(frames) < 30:
        frames += parser.feed(bytes(dev.read(0x81, 3072)))
    c = codec("YUYV")
    grey = c.encode(np.full((48, 64, 3), 128, np.uint8)).tobytes()
    black = c.encode(np.zeros((48, 64, 3), np.uint8)).tobytes()
    plan = FaultPlan.parse(faults)
    seen = dict.fromkeys(IMAGE_FAULTS, 0)
    for k, f in enumerate(frames):  # no drops: the k-th frame read is frame k of the stream
        kind = plan.first_of(IMAGE_FAULTS if k else IMAGE_FAULTS[:2], k)
        want = {"grey": grey, "black": black, "frozen": frames[k - 1].data}.get(kind)
        assert (f.data == want) if kind else f.data not in (grey, black)
        seen[kind or "grey"] += kind is not None
    st = fn.fault_stats
    assert (st.grey_frames, st.black_frames, st.frozen_frames) == tuple(seen.values()) and all(seen.values())


def test_a_register_reset_is_a_control_event_for_a_subscribed_program_under_rollcam_run():
    """A program subscribed to V4L2_EVENT_CTRL for the exposure hears of the reset another program's stream met:
    the pending event (merged per control, as the kernel's) carries the default value, not the one set."""
    need("v4l2-ctl")
    source = "emu:imx219?size=160x120&format=YUYV&scene=flat&faults=regreset=10,seed=2"
    with serving([("/dev/video0", source)], realtime=False) as s:
        default = s.nodes["/dev/video0"].driver.ctrl_defaults["exposure"]
        got = python_under(s, """
            import fcntl, json, os, subprocess
            from rollcam.emu.v4l2 import abi, raw
            fd = os.open("/dev/video0", os.O_RDWR)
            fcntl.ioctl(fd, abi.REQUESTS["SUBSCRIBE_EVENT"][0], bytes(abi.EventSubscription(3, raw.CID.EXPOSURE)))
            subprocess.run(["v4l2-ctl", "-d", "/dev/video0", "--set-ctrl=exposure=100", "--stream-mmap",
                            "--stream-count=30", "--stream-to=/dev/null"], check=True, capture_output=True)
            buf = bytearray(bytes(abi.Event()))
            fcntl.ioctl(fd, abi.REQUESTS["DQEVENT"][0], buf)
            ev = abi.Event.from_buffer_copy(buf)
            c = ev.u.ctrl
            print(json.dumps({"type": ev.type, "id": ev.id, "value": c.value64, "changes": c.changes}))
        """)
        resets = s.nodes["/dev/video0"].driver.fault_stats.register_resets
    assert got["type"] == 3 and got["id"] == raw.CID.EXPOSURE and got["changes"] & 1  # V4L2_EVENT_CTRL_CH_VALUE
    assert got["value"] == default != 100 and resets >= 1



def test_rollcam_capture_writes_the_defects_truth_into_frames_jsonl(tmp_path):
    from rollcam.host.cli import main

    out = tmp_path / "cap"
    uri = "emu:imx219?size=320x240&scene=street&format=RG10&faults=dead=25,stuck=25,burst=100,burst_px=50,seed=4"
    assert main(["capture", uri, "--frames", "2", "--out", str(out)]) == 0
    recs = [json.loads(line) for line in (out / "frames.jsonl").read_text().splitlines()]
    assert len(recs) == 2
    for r in recs:
        d = r["defects"]
        img = cv2.imread(str(out / r["file"]), cv2.IMREAD_UNCHANGED)
        assert img.shape == (240, 320) and img.dtype == np.uint16
        assert all(img[y, x] == 0 for x, y in d["dead"]) and all(img[y, x] == v for x, y, v in d["stuck"])
        assert d["burst"]["length"] == 50 and len(d["dead"]) == len(d["stuck"]) == 25
