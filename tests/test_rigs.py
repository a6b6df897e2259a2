"""Multi-camera rigs (rollcam.firmware.rig, docs/rigs.md): one scene, N cameras, one world clock; hardware sync or
free-running clocks with injected offset, drift and jitter, and what a host measures from the timestamps."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import threading

import numpy as np
import pytest
from interrupts import interrupt
from programs import python_under
from rollcam.common.errors import ConfigError, SourceError
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.rig import CameraClock, LiveRig, Rig, RigSpec, world_row_times_ns
from rollcam.firmware.spec import CameraSpec
from rollcam.host import open_camera
from rollcam.host.servers.devnodes import serving
from rollcam.host.sources.emu import device_spec

FLAT = {"scene": "flat", "size": "160x120"}  # cheap to render: these tests are about time


def frames(uri: str, n: int) -> list:
    with open_camera(uri) as src:
        return [src.read() for _ in range(n)]


def test_hw_sync_starts_every_camera_at_one_world_instant_and_offsets_the_device_clocks_exactly():
    rig = "stereo,baseline=0.12,sync=hw,offset_ns=0/1500"
    left = frames(f"emu:imx219?scene=flat&size=160x120&rig={rig}&rig_cam=0", 4)
    right = frames(f"emu:imx219?scene=flat&size=160x120&rig={rig}&rig_cam=1", 4)
    for a, b in zip(left, right, strict=True):
        assert a.sequence == b.sequence
        assert a.meta["rig"]["world_start_ns"] == b.meta["rig"]["world_start_ns"]  # one trigger
        assert b.timestamp_ns - a.timestamp_ns == 1500  # exactly the injected offset
        assert np.array_equal(world_row_times_ns(a), world_row_times_ns(b))  # same sensor: same line timing
        assert int(b.row_times_ns[0] - a.row_times_ns[0]) == 1500
    # the device clock of camera 0 is the world clock; the frames come one trigger period apart
    assert [f.timestamp_ns for f in left] == [f.meta["rig"]["world_start_ns"] for f in left]


def test_hw_sync_with_drift_keeps_the_world_instant_and_the_device_skew_grows_by_the_ppm():
    rig = Rig(RigSpec.parse("stereo,sync=hw,ppm=0/50"), CameraSpec.from_options("imx219", FLAT))
    k = 3000  # 100 s of frames at 30 fps: the schedule is closed form, only two frames are rendered
    a0, b0, ak, bk = rig.frame(0, 0), rig.frame(1, 0), rig.frame(0, k), rig.frame(1, k)
    assert ak.meta["rig"]["world_start_ns"] == bk.meta["rig"]["world_start_ns"]
    world = ak.meta["rig"]["world_start_ns"] - a0.meta["rig"]["world_start_ns"]
    measured_ppm = ((bk.timestamp_ns - b0.timestamp_ns) - (ak.timestamp_ns - a0.timestamp_ns)) / world * 1e6
    assert measured_ppm == pytest.approx(50, abs=1e-4)  # whole-ns device clocks: 1 ns in 100 s is 1e-5 ppm


def test_free_running_drift_is_what_a_host_measures_from_the_timestamps():
    # Camera 1's oscillator is 25 ppm fast, with 200 ns of timestamp jitter. A host compares the two streams'
    # timestamps against the time they arrive (here the truth's world start) by a least-squares line.
    rig_text = "stereo,sync=free,offset_ns=0/-40000,ppm=0/25,jitter_ns=0/200,seed=4"
    rig = Rig(RigSpec.parse(rig_text), CameraSpec.from_options("imx219", FLAT))
    seqs = [0, 1, 2, 500, 1000, 3000, 6000, 9000]
    for cam, ppm in ((0, 0.0), (1, 25.0)):
        got = [rig.frame(cam, k) for k in seqs]
        world = np.array([f.meta["rig"]["world_start_ns"] for f in got], dtype=np.float64)
        device = np.array([f.timestamp_ns for f in got], dtype=np.float64)
        slope = np.polyfit(world - world[0], device - device[0], 1)[0]
        assert (slope - 1) * 1e6 == pytest.approx(ppm, abs=0.01)  # 200 ns over 300 s: 0.001 ppm
        # free-running: every camera's timestamps advance by its own nominal period on its own clock
        timing = rig.cameras[cam].spec.settings.timing
        start = [f.meta["rig"]["device_start_ns"] for f in got]
        assert start[4] == timing.frame_start_ns(1000, start[0])
        assert start[0] == (rig.rig.clocks[1].device_ns(0) if cam else 0)
    # ... so the cameras' frames of one index drift apart in world time: camera 1's period is P / (1 + 25 ppm)
    a, b = rig.frame(0, 9000), rig.frame(1, 9000)
    skew = a.meta["rig"]["world_start_ns"] - b.meta["rig"]["world_start_ns"]
    elapsed = a.meta["rig"]["world_start_ns"]
    assert skew == pytest.approx(elapsed * 25e-6 / (1 + 25e-6), abs=2)


def test_jitter_is_seeded_and_bounded():
    clock = CameraClock(jitter_ns=300, seed=9, index=1)
    draws = [clock.jitter(k) for k in range(2000)]
    assert max(abs(j) for j in draws) <= 300
    assert max(draws) > 250 and min(draws) < -250  # uniform over the whole range, not a sliver of it
    assert draws == [CameraClock(jitter_ns=300, seed=9, index=1).jitter(k) for k in range(2000)]
    assert draws != [CameraClock(jitter_ns=300, seed=10, index=1).jitter(k) for k in range(2000)]
    rig = "stereo,jitter_ns=300,seed=9"
    one = frames(f"emu:imx219?scene=flat&size=160x120&rig={rig}&rig_cam=1", 3)
    two = frames(f"emu:imx219?scene=flat&size=160x120&rig={rig}&rig_cam=1", 3)
    assert [f.timestamp_ns for f in one] == [f.timestamp_ns for f in two]
    for f in one:
        t = f.meta["rig"]
        assert f.timestamp_ns - t["device_start_ns"] == t["jitter_ns"] and abs(t["jitter_ns"]) <= 300
        assert int(f.row_times_ns[0]) - f.timestamp_ns == int(one[0].row_times_ns[0]) - one[0].timestamp_ns


@pytest.mark.parametrize("w", [0, 1, 999, 10**9 + 7, 86_400 * 30 * 10**9])
def test_clock_is_integer_and_its_inverse_is_exact(w):
    clock = CameraClock(offset_ns=-1234, ppm=-17.5)
    d = clock.device_ns(w)
    assert isinstance(d, int) and d == (w - 1234) * (2_000_000 - 35) // 2_000_000  # floor, exact at any age
    assert clock.world_ns(d) == w


def test_stereo_disparity_of_a_still_walker_is_baseline_times_focal_over_depth():
    b = 0.3
    spec = CameraSpec.from_options("imx219", {"scene": "street", "speed": "static", "pedestrians": "6", "seed": "3",
                                              "size": "640x480", "noise": "off"})
    rig = Rig(RigSpec.parse(f"stereo,baseline={b}"), spec)
    left, right = rig.frame(0, 0), rig.frame(1, 0)
    cam = rig.cameras[0].synthetic.camera
    assert rig.cameras[1].synthetic.camera.position_m[0] == pytest.approx(cam.position_m[0] + b * math.cos(
        math.radians(cam.yaw_deg)))
    yaw, pitch = math.radians(cam.yaw_deg), math.radians(cam.pitch_deg)
    forward = np.array([math.sin(yaw) * math.cos(pitch), math.cos(yaw) * math.cos(pitch), math.sin(pitch)])
    boxes = {o.id: o.box_gs for o in right.objects if o.box_gs is not None}
    checked = 0
    for walker in rig.cameras[0].synthetic.scene.pedestrians:
        obj = next((o for o in left.objects if o.id == walker.id and o.box_gs is not None), None)
        if obj is None or walker.id not in boxes or obj.visible < 0.9:
            continue
        x0, y0, x1, y1 = obj.box_gs
        if x0 <= 1 or x1 >= 639 or boxes[walker.id][0] <= 1 or x1 - x0 < 6:
            continue
        half = walker.lane_half_length_m  # the walk's triangle wave at t = 0 (speed static)
        m = walker.start_offset_m % (4 * half)
        y = -half + m if m < 2 * half else half - (m - 2 * half)
        root = np.array([walker.lane_x_m, walker.lane_y_center_m + y * walker.direction, walker.height_m / 2])
        depth = float((root - np.array(cam.position_m)) @ forward)
        expected = b * cam.fx_px / depth
        truth = (x0 + x1) / 2 - (boxes[walker.id][0] + boxes[walker.id][2]) / 2
        assert truth == pytest.approx(expected, abs=1.0)
        assert expected > 3  # a disparity worth measuring
        # and in the pixels: the left camera's patch of the walker is found that far left in the right image
        r0, r1, c0, c1 = int(y0), int(math.ceil(y1)), int(x0), int(math.ceil(x1))
        patch = left.data[r0:r1, c0:c1].astype(np.float64)
        shifts = range(0, int(expected) + 6)
        ssd = [np.sum((right.data[r0:r1, c0 - s:c1 - s].astype(np.float64) - patch) ** 2) if c0 - s >= 0 else np.inf
               for s in shifts]
        assert int(np.argmin(ssd)) == pytest.approx(expected, abs=1.0)
        checked += 1
    assert checked >= 1


def test_surround_turns_each_camera_by_360_over_n():
    rig = Rig(RigSpec.parse("surround,n=4,radius=0.1"), CameraSpec.from_options("imx219", FLAT))
    yaws = [c.spec.mount_yaw_deg for c in rig.cameras]
    assert yaws == [0.0, 90.0, 180.0, 270.0]
    assert rig.cameras[0].spec.mount_m == (0.0, 0.0, 0.0)
    # around a centre 0.1 m behind camera 0: camera 1 to its right-back, camera 2 0.2 m behind it, facing back
    assert rig.cameras[1].spec.mount_m == pytest.approx((0.1, -0.1, 0.0))
    assert rig.cameras[2].spec.mount_m == pytest.approx((0.0, -0.2, 0.0))
    c0, c2 = rig.cameras[0].synthetic.camera, rig.cameras[2].synthetic.camera
    assert math.dist(c0.position_m, c2.position_m) == pytest.approx(0.2)
    assert c2.yaw_deg == pytest.approx(c0.yaw_deg + 180)
    assert [f.meta["rig"]["camera"] for f in (rig.frame(i, 0) for i in range(4))] == [0, 1, 2, 3]


@pytest.mark.parametrize(("text", "message"), [
    ("trinocular", "rig kind 'trinocular' is not one of"),
    ("stereo,n=3", "a stereo rig has 2 cameras"),
    ("stereo,sync=maybe", "rig sync='maybe' is not one of"),
    ("stereo,ppm=1/2/3", "gives 3 values for 2 cameras"),
    ("stereo,ppm=5000", "beyond +-1000"),
    ("stereo,baseline=-1", "rig baseline='-1' is invalid"),
    ("stereo,radius=1", "rig key 'radius' is not one of"),
    ("surround,n=0", "rig n='0' is invalid"),
    ("stereo,jitter_ns=x", "rig jitter_ns='x' is invalid"),
    ("stereo,offset", "rig part 'offset' is not key=value"),
])
def test_bad_rig_text_is_a_one_line_error(text, message):
    with pytest.raises(ConfigError, match=message.replace("+", r"\+")) as exc:
        RigSpec.parse(text)
    assert "\n" not in str(exc.value)
    with pytest.raises(SourceError, match="source 'emu:imx219"):
        open_camera(f"emu:imx219?scene=flat&rig={text}")


def test_rig_cam_out_of_range_or_without_rig_is_an_error():
    with pytest.raises(SourceError, match=r"rig_cam=2 is not a camera of the 2-camera rig \(0..1\)"):
        open_camera("emu:imx219?scene=flat&rig=stereo&rig_cam=2")
    with pytest.raises(SourceError, match="rig_cam= needs rig="):
        open_camera("emu:imx219?scene=flat&rig_cam=1")


def test_a_rig_cameras_frames_match_a_lone_camera_at_the_same_place_and_time():
    # One home for the camera: a rig camera is the emu: camera moved by mount_m, rendered at its world time.
    spec = CameraSpec.from_options("imx219", {**FLAT, "mount_m": "0.12,0,0"})
    rig = Rig(RigSpec.parse("stereo,baseline=0.12,offset_ns=0/777"), CameraSpec.from_options("imx219", FLAT))
    lone = frames("emu:imx219?scene=flat&size=160x120&mount_m=0.12,0,0", 2)[1]
    got = rig.frame(1, 1)
    assert spec == rig.cameras[1].spec
    assert np.array_equal(lone.data, got.data)
    assert got.timestamp_ns == lone.timestamp_ns + 777


def _read_stream(url: str, n: int, out: list) -> None:
    with open_camera(url) as src:
        while len(out) < n:
            frame = src.read()
            if frame is None:
                return
            out.append(frame)


def _serve_rig(rig: str, n: int) -> tuple[dict, list[list], str]:
    """``rollcam emulate --rig RIG`` on free ports, ``n`` frames read from each camera's MJPEG stream at once by the
    ``http://`` source, then stopped by SIGINT: the JSON line, the frames per camera and stderr."""
    cmd = [sys.executable, "-m", "rollcam.host.cli", "emulate", "imx219", "--size", "160x120", "--scene", "flat",
           "--rig", rig, "--http", "127.0.0.1:0", "--json", "--duration", "120"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        info = json.loads(proc.stdout.readline())
        urls = [c["http"]["url"] for c in info["cameras"]]
        assert len(set(urls)) == len(urls) == info["rig"]["n"]
        got: list[list] = [[] for _ in urls]
        readers = [threading.Thread(target=_read_stream, args=(u, n, g)) for u, g in zip(urls, got, strict=True)]
        for t in readers:
            t.start()
        for t in readers:
            t.join(timeout=90)
        _out, err = interrupt(proc, timeout_s=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert "camera 1: stopped;" in err
    return info, got, err


def test_rollcam_emulate_serves_a_hw_synchronised_rig_whose_skew_a_client_measures_from_the_timestamps():
    # Two cameras of one rig on two MJPEG servers; camera 1's clock is 5 ms ahead and 1000 ppm fast. A client
    # reading both streams pairs frames of one trigger by timestamp and measures offset and drift from them.
    info, got, _err = _serve_rig("stereo,sync=hw,offset_ns=0/5000000,ppm=0/1000", 40)
    assert info["rig"]["clocks"][1] == {"offset_ns": 5000000, "ppm": 1000.0, "jitter_ns": 0}
    clock = CameraClock(offset_ns=5000000, ppm=1000.0)
    timing = CameraSpec.from_options("imx219", FLAT).settings.timing
    a_ts = {f.timestamp_ns for f in got[0]}
    pairs = []
    for f in got[1]:
        world = clock.world_ns(f.timestamp_ns)  # every camera-1 frame started on a trigger slot of the world clock
        k = round(world / timing.frame_period_ns)
        assert clock.device_ns(timing.frame_start_ns(k)) == f.timestamp_ns
        if timing.frame_start_ns(k) in a_ts:  # camera 0's clock is the world's: its frame of the same trigger
            pairs.append((timing.frame_start_ns(k), f.timestamp_ns))
    assert len(pairs) >= 10, (len(got[0]), len(got[1]))
    a = np.array([p[0] for p in pairs], dtype=np.float64)
    skew = np.array([p[1] - p[0] for p in pairs], dtype=np.float64)
    slope, intercept = np.polyfit(a - a[0], skew, 1)
    assert slope * 1e6 == pytest.approx(1000, abs=0.01)  # the drift a host measures: 1 ns over > 0.3 s
    assert intercept == pytest.approx(clock.device_ns(int(a[0])) - a[0], abs=2)
    assert skew.min() >= 5000000


def test_rollcam_emulate_serves_a_free_running_rig_each_camera_on_its_own_clock():
    # Camera 1's clock is 1 s ahead and 1000 ppm fast. Each stream's timestamps advance by exactly its own
    # nominal frame period on its own clock, and against the host's arrival times (the same monotonic clock the
    # emulator's world runs on) the client sees camera 1 about 1.001 s ahead.
    info, got, _err = _serve_rig("stereo,sync=free,offset_ns=0/1000000000,ppm=0/1000", 30)
    timing = CameraSpec.from_options("imx219", FLAT).settings.timing
    lead = []
    for frames_ in got:
        assert len(frames_) >= 10
        first = frames_[0]
        for f in frames_[1:]:
            # whole ns: a frame starts at floor(k * period) from the stream's first, so steps differ by <= 1 ns
            assert abs(f.timestamp_ns - first.timestamp_ns - timing.frame_start_ns(f.sequence - first.sequence)) <= 1
        lead.append(np.median([f.timestamp_ns - f.meta["arrival_ns"] for f in frames_]))
    assert lead[1] - lead[0] == pytest.approx(1_001_000_000, abs=15_000_000)  # delivery latency is common
    # --json says where the world clock starts on the host's: camera 0 (the world's clock) then arrives after
    # its timestamp by exposure, readout and delivery, well under a second.
    world0 = info["rig"]["world_start_monotonic_ns"]
    after = [f.meta["arrival_ns"] - (world0 + f.timestamp_ns) for f in got[0]]
    assert min(after) > 0 and np.median(after) < 1_000_000_000


@pytest.mark.parametrize(("rig", "message"), [
    ("stereo,sync=maybe", "rig sync='maybe' is not one of ('hw', 'free')"),
    ("quad", "rig kind 'quad' is not one of ('stereo', 'surround')"),
])
def test_rollcam_emulate_bad_rig_is_a_one_line_usage_error(rig, message):
    proc = subprocess.run([sys.executable, "-m", "rollcam.host.cli", "emulate", "imx219", "--rig", rig],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rollcam: error:") and message in lines[0], proc.stderr


def test_a_live_free_running_rig_reads_each_cameras_clock_from_the_one_world_clock():
    # The world clock is passed in (a test's own), so the device clocks and the frames' truth are exact.
    now = [10**12]
    rig = LiveRig(RigSpec.parse("stereo,sync=free,offset_ns=0/-2000000,ppm=0/300"),
                  CameraSpec.from_options("imx219", FLAT), world=lambda: now[0])
    left, right = rig.cameras
    assert right.clock_ns() == 0  # the world starts where no camera's clock reads below 0
    now[0] += 123_456_789
    world = rig.world_ns()
    assert world == 123_456_789 + 2_000_000 == left.clock_ns()
    assert right.clock_ns() == rig.rig.clocks[1].device_ns(world) == 123_456_789 * 1_000_300 // 1_000_000
    rig.start()
    try:
        for cam, clock in zip(rig.cameras, rig.rig.clocks, strict=True):
            plan = cam.plan_next()
            frame = cam.render(plan)
            truth = frame.meta["rig"]
            assert frame.timestamp_ns == plan.start_ns == cam.clock_ns()  # started now, on its own clock
            assert truth["world_start_ns"] == world == clock.world_ns(plan.start_ns)
            assert cam.plan_next().start_ns - plan.start_ns == cam.spec.settings.timing.frame_start_ns(1)
    finally:
        rig.close()
    rig.close()  # twice is harmless


def test_a_trigger_at_a_device_instant_starts_the_frame_then():
    now = [5_000_000]
    cam = FirmwareCamera(CameraSpec.from_options("imx219", FLAT), clock=lambda: now[0], boot_ns=0)
    cam.set_trigger_mode("external")
    cam.stream_on()
    assert cam.trigger(4_000_000) == 4_000_000  # the line's edge, stamped before the call came
    assert cam.plan_next().start_ns == 4_000_000
    assert cam.trigger() == max(5_000_000, cam.schedule(4_000_000).frame_due_ns(0))


def test_hw_sync_refuses_an_exposure_and_readout_longer_than_the_trigger_period():
    with pytest.raises(SourceError, match=r"rig sync=hw: exposure \+ readout \(\d+ ns\) is longer than the trigger"):
        open_camera("emu:imx219?scene=flat&size=160x120&exposure_us=30000&rig=stereo")
    frames("emu:imx219?scene=flat&size=160x120&exposure_us=30000&rig=stereo,sync=free", 1)  # free-running: fine


def test_rollcam_run_gives_a_program_a_hw_synchronised_stereo_pair_as_two_v4l2_devices():
    # Two /dev/video nodes of one rig (one trigger line, camera 1's clock 5 ms ahead and 1000 ppm fast); the
    # program reads both with rollcam's v4l2: source (ioctls through the preload library) and gets the skew
    # in the buffers' timestamps (struct timeval: whole microseconds).
    rig = "stereo,sync=hw,offset_ns=0/5000000,ppm=0/1000"
    base = f"emu:imx219?scene=flat&size=160x120&rig={rig}"
    with serving([("/dev/video0", base + "&rig_cam=0"), ("/dev/video1", base + "&rig_cam=1")]) as server:
        r = python_under(server, """
            import json
            from rollcam.host import open_camera
            out = {"0": [], "1": []}
            with open_camera("v4l2:/dev/video0") as a, open_camera("v4l2:/dev/video1") as b:
                while min(len(v) for v in out.values()) < 15:
                    for key, cam in (("0", a), ("1", b)):
                        f = cam.read()
                        out[key].append(int(f.timestamp_ns))
            print(json.dumps(out))
        """)
    clock = CameraClock(offset_ns=5000000, ppm=1000.0)
    timing = CameraSpec.from_options("imx219", FLAT).settings.timing
    slots = {}
    for ts in r["0"]:  # camera 0's clock is the world's: each frame on a trigger slot
        k = round(ts / timing.frame_period_ns)
        assert abs(ts - timing.frame_start_ns(k)) < 1000
        slots[k] = ts
    pairs = []
    for ts in r["1"]:
        k = round(clock.world_ns(ts) / timing.frame_period_ns)
        assert abs(ts - clock.device_ns(timing.frame_start_ns(k))) < 1000  # its own clock's reading of the slot
        if k in slots:
            pairs.append((slots[k], ts))
    assert len(pairs) >= 5
    a = np.array([p[0] for p in pairs], dtype=np.float64)
    skew = np.array([p[1] - p[0] for p in pairs], dtype=np.float64)
    assert np.all(np.abs(skew - (5000000 * 1.001 + a * 1e-3)) < 2000)  # offset and drift, to the microsecond


def test_doors_without_rigs_refuse_rig_and_one_rig_camera_is_one_device():
    with pytest.raises(SourceError, match="rig= is for emu: sources, rollcam emulate --rig and rollcam run devices"):
        device_spec("emu:imx219?rig=stereo")  # the picamera2 stand-in's door
    uri = "emu:imx219?scene=flat&size=160x120&rig=stereo&rig_cam=1"
    with pytest.raises(ConfigError, match="is a rig camera another device already serves"), \
            serving([("/dev/video0", uri), ("/dev/video1", uri)]):
        pass
