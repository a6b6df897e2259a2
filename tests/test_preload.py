"""``rollcam run``: unmodified programs (v4l2-ctl, v4l2-compliance, ffmpeg, GStreamer, OpenCV, linuxpy) on an
emulated /dev/video0 served by one shared device server; bad input from a program; a crash mid-stream."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from programs import need
from programs import python_under as python
from programs import run_under as run
from rollcam.common.errors import RollcamError
from rollcam.emu import preload as preload_package
from rollcam.emu.preload import LIBRARY_NAME
from rollcam.host.servers.devnodes import program_environment, serving

LIB = Path(preload_package.__file__).with_name(LIBRARY_NAME)
pytestmark = pytest.mark.skipif(not LIB.is_file(), reason=f"{LIB} not built (pip install -e . with a C compiler)")
SOURCE = "emu:imx219?size=640x480&scene=street&format=YUYV"
FRAME = 640 * 480 * 2


@pytest.fixture(scope="module")
def server():
    with serving([("/dev/video0", SOURCE), ("/dev/video3", "emu:ov9281?size=640x400")]) as s:
        yield s


def test_v4l2_ctl_all_list_formats_and_devices(server):
    need("v4l2-ctl")
    out = run(server, "v4l2-ctl", "-d", "/dev/video0", "--all").stdout
    assert "rollcam imx219 emulator" in out and "Read/Write" in out and "Streaming" in out
    assert "line_time_ns" in out and "readout_direction" in out and "vertical_blanking" in out
    fmts = run(server, "v4l2-ctl", "-d", "/dev/video0", "--list-formats-ext").stdout
    assert "'YUYV'" in fmts and "'pRAA'" in fmts and "'RG10'" in fmts and "640x480" in fmts
    assert "/dev/video3" in run(server, "v4l2-ctl", "--list-devices").stdout


def test_v4l2_ctl_set_ctrl_reaches_the_camera(server):
    need("v4l2-ctl")
    run(server, "v4l2-ctl", "-d", "/dev/video0", "--set-ctrl=exposure=321")
    assert server.nodes["/dev/video0"].driver.camera.get_control("exposure") == 321
    assert "exposure: 321" in run(server, "v4l2-ctl", "-d", "/dev/video0", "--get-ctrl=exposure").stdout


def _stream(server, tmp_path: Path, name: str, *extra: str, count: int = 4) -> np.ndarray:
    out = tmp_path / name
    run(server, "v4l2-ctl", "-d", "/dev/video0", "--set-fmt-video=width=640,height=480,pixelformat=YUYV", *extra,
        "--stream-mmap", f"--stream-count={count}",
        f"--stream-to={out}")
    data = np.fromfile(out, np.uint8)
    assert data.size == count * FRAME
    return data.reshape(count, 480, 640, 2)


def test_v4l2_ctl_streams_the_scene_and_an_exposure_change_shows(server, tmp_path):
    need("v4l2-ctl")
    short = _stream(server, tmp_path, "short.yuyv", "--set-ctrl=exposure=20")
    long = _stream(server, tmp_path, "long.yuyv", "--set-ctrl=exposure=1500")
    luma_short, luma_long = short[-1, :, :, 0].astype(float), long[-1, :, :, 0].astype(float)
    assert luma_long.std() > 10  # the street, not a flat test pattern
    assert luma_long.mean() > luma_short.mean() + 20


@pytest.mark.slow
def test_v4l2_ctl_streams_100_frames(server, tmp_path):
    need("v4l2-ctl")
    _stream(server, tmp_path, "many.yuyv", count=100)


def test_v4l2_compliance_streaming_has_no_failures(server):
    need("v4l2-compliance")
    p = run(server, "v4l2-compliance", "-d", "/dev/video3", "-s", timeout=300, check=False)
    summary = [line for line in p.stdout.splitlines() if line.startswith("Total for")]
    fails = "\n".join(line for line in p.stdout.splitlines() if "fail:" in line)  # the failing checks, by name
    assert summary and ", Failed: 0," in summary[-1], fails + "\n" + p.stdout[-3000:]
    assert p.returncode == 0


def test_v4l2_compliance_on_a_size_no_mode_has():
    """``size=640x480`` on an imx477 (no such mode) is offered and kept: TRY_FMT(G_FMT) and S_FMT(G_FMT) give G_FMT
    back (they gave the nearest mode, 1332x990, before)."""
    need("v4l2-compliance")
    with serving([("/dev/video0", "emu:imx477?size=640x480&scene=flat")]) as s:
        p = run(s, "v4l2-compliance", "-d", "/dev/video0", timeout=300, check=False)
    summary = [line for line in p.stdout.splitlines() if line.startswith("Total for")]
    fails = "\n".join(line for line in p.stdout.splitlines() if "fail:" in line)
    assert summary and ", Failed: 0," in summary[-1], fails + "\n" + p.stdout[-3000:]


@pytest.mark.slow
def test_v4l2_compliance_every_format_has_no_failures(server):
    need("v4l2-compliance")
    p = run(server, "v4l2-compliance", "-d", "/dev/video3", "-s", "-f", timeout=900, check=False)
    summary = [line for line in p.stdout.splitlines() if line.startswith("Total for")]
    fails = "\n".join(line for line in p.stdout.splitlines() if "fail:" in line)  # the failing checks, by name
    assert summary and ", Failed: 0," in summary[-1], fails + "\n" + p.stdout[-3000:]


def test_ffmpeg_reads_frames(server, tmp_path):
    need("ffmpeg")
    out = tmp_path / "ff.yuyv"
    run(server, "ffmpeg", "-hide_banner", "-loglevel", "error", "-f", "v4l2", "-input_format", "yuyv422",
        "-i", "/dev/video0", "-frames:v", "5", "-f", "rawvideo", "-y", str(out))
    frames = np.fromfile(out, np.uint8).reshape(-1, 480, 640, 2)
    assert len(frames) == 5 and frames[-1, :, :, 0].std() > 10


def test_gstreamer_v4l2src_reads_frames(server):
    need("gst-launch-1.0")
    p = run(server, "gst-launch-1.0", "-q", "v4l2src", "device=/dev/video0", "num-buffers=5", "!",
            "video/x-raw,format=YUY2,width=640,height=480", "!", "fakesink")
    assert p.returncode == 0


def test_opencv_reads_frames_and_sets_the_exposure(server):
    r = python(server, """
        import json, cv2
        out = {}
        for key, arg in (("index", (0,)), ("path", ("/dev/video0", cv2.CAP_V4L2))):
            cap = cv2.VideoCapture(*arg)
            assert cap.isOpened()
            means = []
            for exposure in (2, 150):
                assert cap.set(cv2.CAP_PROP_EXPOSURE, exposure)
                for _ in range(4):
                    ok, img = cap.read()
                    assert ok
                means.append(float(img.mean()))
            out[key] = {"shape": img.shape, "means": means, "std": float(img.std()),
                        "exposure": cap.get(cv2.CAP_PROP_EXPOSURE)}
            cap.release()
        print(json.dumps(out))
    """)
    for key in ("index", "path"):
        assert r[key]["shape"] == [480, 640, 3] and r[key]["std"] > 10 and r[key]["exposure"] == 150
        assert r[key]["means"][1] > r[key]["means"][0] + 20


def test_linuxpy_streams_and_sets_controls(server):
    pytest.importorskip("linuxpy")
    r = python(server, """
        import json
        from linuxpy.video.device import BufferType, Device
        with Device("/dev/video0") as cam:
            cam.set_format(BufferType.VIDEO_CAPTURE, 640, 480, "YUYV")
            cam.controls.exposure.value = 400
            frames = []
            for frame in cam:
                frames.append((frame.frame_nb, len(frame.data), frame.timestamp))
                if len(frames) == 3:
                    break
            print(json.dumps({"exposure": cam.controls.exposure.value, "frames": frames,
                              "card": cam.info.card}))
    """)
    assert r["exposure"] == 400 and r["card"] == "rollcam imx219 emulator"
    seqs = [f[0] for f in r["frames"]]
    assert all(f[1] == FRAME for f in r["frames"]) and seqs == sorted(set(seqs))


def test_bad_input_gets_linux_errnos(server):
    r = python(server, """
        import errno, fcntl, json, mmap, os
        from rollcam.emu.v4l2 import abi
        R = {k: v[0] for k, v in abi.REQUESTS.items()}
        out = {}
        def err(call):
            try:
                call()
            except OSError as e:
                return errno.errorcode[e.errno]
            return "ok"
        fd = os.open("/dev/video0", os.O_RDWR | os.O_NONBLOCK)
        out["unknown"] = err(lambda: fcntl.ioctl(fd, 0xC0DE56FF, bytearray(16)))
        out["short"] = err(lambda: fcntl.ioctl(fd, R["QUERYCAP"] ^ (104 << 16) ^ (8 << 16), bytearray(8)))
        fcntl.ioctl(fd, R["REQBUFS"], abi.RequestBuffers(count=2, type=1, memory=1))
        out["qbuf"] = err(lambda: fcntl.ioctl(fd, R["QBUF"], abi.Buffer(index=7, type=1, memory=1)))
        out["type"] = err(lambda: fcntl.ioctl(fd, R["QBUF"], abi.Buffer(index=0, type=9, memory=1)))
        out["dqbuf"] = err(lambda: fcntl.ioctl(fd, R["DQBUF"], abi.Buffer(type=1, memory=1)))
        out["mmap"] = err(lambda: mmap.mmap(fd, 4096, mmap.MAP_SHARED, mmap.PROT_READ, offset=0x7000000))
        out["ctrl"] = err(lambda: fcntl.ioctl(fd, R["S_CTRL"], abi.Control(id=0x00980999, value=1)))
        out["readonly"] = err(lambda: fcntl.ioctl(fd, R["S_CTRL"], abi.Control(id=0x009e0902, value=1)))
        out["write"] = err(lambda: os.write(fd, b"x"))
        fd2 = os.open("/dev/video0", os.O_RDWR)
        out["owner"] = err(lambda: fcntl.ioctl(fd2, R["REQBUFS"], abi.RequestBuffers(count=2, type=1, memory=1)))
        os.close(fd2)
        os.close(fd)
        out["closed"] = err(lambda: fcntl.ioctl(fd, R["QUERYCAP"], abi.Capability()))
        print(json.dumps(out))
    """)
    assert r == {"unknown": "ENOTTY", "short": "ENOTTY", "qbuf": "EINVAL", "type": "EINVAL", "dqbuf": "EINVAL",
                 "mmap": "EINVAL", "ctrl": "EINVAL", "readonly": "EACCES", "write": "EINVAL", "owner": "EBUSY",
                 "closed": "EBADF"}


def test_a_program_killed_mid_stream_frees_its_buffers_and_the_other_device_streams_on(server, tmp_path):
    need("v4l2-ctl")
    env = program_environment(server)
    other = subprocess.Popen(["v4l2-ctl", "-d", "/dev/video3", "--stream-mmap", "--stream-count=40",
                              f"--stream-to={tmp_path / 'other.raw'}"], env=env, stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE)
    victim = subprocess.Popen(["v4l2-ctl", "-d", "/dev/video0", "--stream-mmap", "--stream-count=100000"],
                              env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    node = server.nodes["/dev/video0"]
    try:
        for _ in range(300):
            if node.driver.queue.streaming:
                break
            assert victim.poll() is None, victim.stderr.read()
            time.sleep(0.05)
        assert node.driver.queue.streaming
        victim.kill()
        victim.wait(30)
        for _ in range(200):
            if node.owner is None:
                break
            time.sleep(0.05)
        assert node.owner is None and not node.driver.queue.slots  # freed when its connection ended
        _stream(server, tmp_path, "after.yuyv", count=2)  # the next program gets the device
        assert other.wait(120) == 0
        assert os.path.getsize(tmp_path / "other.raw") == 40 * server.nodes["/dev/video3"].driver.fmt.sizeimage
    finally:
        for p in (victim, other):
            if p.poll() is None:
                p.kill()
                p.wait()


def test_rollcam_run_returns_the_program_status_and_cleans_up(tmp_path):
    from rollcam.host.cli import main

    script = tmp_path / "probe.sh"
    script.write_text(f'#!/bin/sh\necho "$ROLLCAM_PRELOAD_SOCKET" > {tmp_path}/sock\n'
                      f'test -c /dev/video2 || exit 9\nexit 3\n')
    script.chmod(0o755)
    assert main(["run", "--device", "/dev/video2=imx219", "--", str(script)]) == 3
    sock = Path((tmp_path / "sock").read_text().strip())
    assert sock.name == "v4l2.sock" and not sock.parent.exists()
    assert main(["run", "--device", "/dev/video0=emu:nosuch", "--", "true"]) == 2


def test_the_child_environment_preloads_the_library_and_puts_the_shims_first(server):
    from rollcam.host.servers.standins import shims_path

    base = {"PATH": "/usr/bin", "PYTHONPATH": "/elsewhere", "LD_PRELOAD": "/opt/other.so"}
    env = program_environment(server, base)
    assert env["LD_PRELOAD"].split() == [str(LIB), "/opt/other.so"]
    assert env["ROLLCAM_PRELOAD_DEVICES"] == "/dev/video0,/dev/video3"
    assert env["PYTHONPATH"] == f"{shims_path()}{os.pathsep}/elsewhere"
    assert (shims_path() / "picamera2" / "__init__.py").is_file()


def test_a_device_uri_carries_its_fault_plan_to_the_driver():
    import rollcam.host.servers.devnodes as hp

    camera, plan = hp.build_camera("emu:imx219?size=160x120&faults=drop=50%,seed=3")
    assert plan.to_text() and "drop" in plan.to_text() and camera.size == (160, 120)
    assert not hp.build_camera("imx219")[1].to_text()
    with pytest.raises(RollcamError, match="nosuch"):
        hp.build_camera("emu:imx219?faults=nosuch=1")


def test_a_picamera2_script_under_rollcam_run_gets_the_stand_in_on_the_first_device(tmp_path):
    from rollcam.host.cli import main

    script = tmp_path / "pi.py"
    out = tmp_path / "out.json"
    script.write_text(textwrap.dedent(f"""
        import json
        from picamera2 import Picamera2
        with Picamera2() as cam:
            json.dump({{"model": cam.camera_properties["Model"], "file": __import__("picamera2").__file__}},
                      open({str(out)!r}, "w"))
    """))
    assert main(["run", "--device", "/dev/video0=imx477", "--", sys.executable, str(script)]) == 0
    got = json.loads(out.read_text())
    assert got["model"] == "imx477" and "/host/shims/picamera2/" in got["file"]


def test_faults_reach_the_preloaded_device_and_an_unplugged_one_comes_back_after_close(tmp_path):
    need("v4l2-ctl")
    source = "emu:imx219?size=160x120&format=YUYV&faults=s_ctrl=EIO@1,disconnect=2"
    with serving([("/dev/video0", source)], realtime=False) as s:
        driver = s.nodes["/dev/video0"].driver
        bad = run(s, "v4l2-ctl", "-d", "/dev/video0", "--set-ctrl=exposure=300", check=False)
        assert bad.returncode != 0 and driver.fault_stats.request_errors == 1  # the injected EIO, once
        run(s, "v4l2-ctl", "-d", "/dev/video0", "--set-ctrl=exposure=300")  # the second S_CTRL goes through
        out = run(s, "v4l2-ctl", "-d", "/dev/video0", "--stream-mmap", "--stream-count=5",
                  f"--stream-to={tmp_path / 'a.raw'}", check=False)
        assert "No such device" in out.stderr and driver.fault_stats.disconnects == 1  # ENODEV after 2 buffers
        assert (tmp_path / "a.raw").stat().st_size <= 2 * 160 * 120 * 2
        # the program closed its file: the device is connected again, as vivid's
        assert "rollcam imx219 emulator" in run(s, "v4l2-ctl", "-d", "/dev/video0", "--all").stdout
