"""The metadata node under ``rollcam run``: a camera with an in-sensor network gets a second /dev/videoN of
type META_CAPTURE whose buffers carry each frame's in-sensor results with the image buffer's sequence and
timestamp; v4l2-ctl lists and streams it, v4l2-compliance passes it, and a Python reader streams both nodes."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from programs import need
from rollcam.emu import preload as preload_package
from rollcam.emu.preload import LIBRARY_NAME
from rollcam.host.servers.devnodes import program_environment, serving

pytest.importorskip("onnx")  # the in-sensor stage counts a network's operations from its graph
LIB = Path(preload_package.__file__).with_name(LIBRARY_NAME)
pytestmark = pytest.mark.skipif(not LIB.is_file(), reason=f"{LIB} not built (pip install -e . with a C compiler)")
SOURCE = "emu:imx219?size=640x480&speed=fast&pedestrians=12&format=YUYV&insensor=personnet-raw"


@pytest.fixture(scope="module")
def server():
    with serving([("/dev/video0", SOURCE), ("/dev/video3", "emu:ov9281?size=640x400")]) as s:
        yield s


def run(server, *argv: str, timeout: float = 180) -> subprocess.CompletedProcess:
    p = subprocess.run(list(argv), env=program_environment(server), capture_output=True, text=True,
                       timeout=timeout)
    assert p.returncode == 0, (p.returncode, p.stdout[-2000:], p.stderr[-2000:])
    return p


def test_only_a_camera_with_a_network_gets_a_metadata_node(server):
    assert sorted(server.nodes) == ["/dev/video0", "/dev/video1", "/dev/video3"]
    need("v4l2-ctl")
    devices = run(server, "v4l2-ctl", "--list-devices").stdout
    assert "/dev/video0\n\t/dev/video1" in devices  # one device, two nodes (one bus_info), as uvcvideo's
    info = run(server, "v4l2-ctl", "-d", "/dev/video1", "--all").stdout
    assert "Metadata Capture" in info.split("Device Caps")[1] and "Video Capture" not in info.split("Device Caps")[1]
    assert "'RCIS' (rollcam In-Sensor Results)" in info and "Buffer Size     : 8192" in info
    fmts = run(server, "v4l2-ctl", "-d", "/dev/video1", "--list-formats-meta").stdout
    assert "[0]: 'RCIS' (rollcam In-Sensor Results)" in fmts


def test_v4l2_compliance_passes_the_metadata_node(server):
    need("v4l2-compliance")
    p = subprocess.run(["v4l2-compliance", "-d", "/dev/video1"], env=program_environment(server),
                       capture_output=True, text=True, timeout=300)
    total = [line for line in p.stdout.splitlines() if line.startswith("Total for")]
    assert total and "Failed: 0" in total[-1], p.stdout[-3000:]


def test_v4l2_ctl_streams_metadata_beside_the_image(server, tmp_path):
    need("v4l2-ctl")
    script = (f"v4l2-ctl -d /dev/video1 --stream-mmap --stream-count=4 --stream-to={tmp_path}/meta.bin --verbose "
              f"> {tmp_path}/meta.log 2>&1 & sleep 1; v4l2-ctl -d /dev/video0 --stream-mmap --stream-count=30 "
              f"--stream-to=/dev/null --verbose > {tmp_path}/img.log 2>&1; wait")
    run(server, "sh", "-c", script)

    def dq(name: str) -> dict[int, str]:
        lines = [x for x in (tmp_path / name).read_text().splitlines() if "cap dqbuf" in x]
        return {int(x.split("seq:")[1].split()[0]): x.split("ts:")[1].split()[0] for x in lines}

    meta, image = dq("meta.log"), dq("img.log")
    assert len(meta) == 4 and all(image.get(seq) == ts for seq, ts in meta.items())  # same sequence, same time
    from rollcam.emu.v4l2.meta import BUFFER_SIZE, unpack

    data = (tmp_path / "meta.bin").read_bytes()
    first = unpack(data[:BUFFER_SIZE] if len(data) > BUFFER_SIZE else data)
    assert first["sequence"] in meta


READER = """
import fcntl, json, mmap, os, select
from rollcam.emu.v4l2 import abi
from rollcam.emu.v4l2.meta import unpack

def req(name):
    return abi.REQUESTS[name][0]

def start(path, buf_type, count=4):
    fd = os.open(path, os.O_RDWR | os.O_NONBLOCK)
    rb = abi.RequestBuffers(count=count, type=buf_type, memory=1)
    fcntl.ioctl(fd, req("REQBUFS"), rb)
    maps = []
    for i in range(rb.count):
        b = abi.Buffer(index=i, type=buf_type, memory=1)
        fcntl.ioctl(fd, req("QUERYBUF"), b)
        maps.append(mmap.mmap(fd, b.length, mmap.MAP_SHARED, mmap.PROT_READ, offset=b.m.offset))
        fcntl.ioctl(fd, req("QBUF"), b)
    fcntl.ioctl(fd, req("STREAMON"), abi.C.c_int(buf_type))
    return fd, maps

meta_fd, meta_maps = start("/dev/video1", 13)  # V4L2_BUF_TYPE_META_CAPTURE
video_fd, video_maps = start("/dev/video0", 1)
images, metas = {}, []
while len(metas) < 6:
    ready, _, _ = select.select([video_fd, meta_fd], [], [], 30)
    assert ready, "no buffer in 30 s"
    for fd in ready:
        buf_type = 13 if fd == meta_fd else 1
        b = abi.Buffer(type=buf_type, memory=1)
        try:
            fcntl.ioctl(fd, req("DQBUF"), b)
        except BlockingIOError:
            continue
        ts = b.timestamp.tv_sec * 1_000_000_000 + b.timestamp.tv_usec * 1000
        if fd == meta_fd:
            doc = unpack(meta_maps[b.index][: b.bytesused])
            metas.append({"seq": b.sequence, "ts": ts, "doc": doc})
        else:
            images[b.sequence] = ts
        fcntl.ioctl(fd, req("QBUF"), b)
print(json.dumps({"images": images, "metas": metas}))
"""


def test_a_python_reader_streams_both_nodes(server):
    p = run(server, sys.executable, "-c", textwrap.dedent(READER))
    out = json.loads(p.stdout.strip().splitlines()[-1])
    images = {int(k): v for k, v in out["images"].items()}
    metas = out["metas"]
    found = 0
    for m in metas:
        doc = m["doc"]
        # The buffer's sequence and timestamp are the image buffer's; the header repeats them (ns precision).
        assert doc["sequence"] == m["seq"] and abs(doc["timestamp_ns"] - m["ts"]) < 1000
        if m["seq"] in images:
            assert abs(images[m["seq"]] - m["ts"]) < 1000
        for r in doc["results"]:
            # A result comes from an earlier frame, done after that frame was whole, before this one is.
            assert r["sequence"] < m["seq"] and r["timestamp_ns"] < r["input_ns"] < r["done_ns"]
            assert r["done_ns"] <= doc["timestamp_ns"] + (r["input_ns"] - r["timestamp_ns"])
            assert r["input_size"] == [640, 480]  # the whole frame fits the default 640x640 input
            found += len(r["detections"])
            assert all(0 <= d["box"][0] < d["box"][2] <= 640 and d["cls"] == 0 for d in r["detections"])
    assert found > 0 and any(m["doc"]["results"] for m in metas)


def test_the_user_space_device_streams_metadata_with_each_buffer():
    from rollcam.common.errors import ConfigError
    from rollcam.emu.v4l2 import Device

    with Device.open("imx219", size=(640, 480), insensor="personnet-raw", realtime=False) as cam:
        bufs = list(cam.stream(buffers=4, frames=4, metadata=True))
        stage = cam.driver.camera.insensor
    assert [b.sequence for b in bufs] == [0, 1, 2, 3]
    for b in bufs:
        assert b.metadata is not None and b.metadata["sequence"] == b.sequence
        assert b.metadata["timestamp_ns"] == b.timestamp_ns
    carried = [r for b in bufs[1:] for r in b.metadata["results"]]
    assert carried and all(r["sequence"] == b.sequence - 1 for b in bufs[1:] for r in b.metadata["results"])
    done = {r.seq: r for r in stage.recent(1 << 62)}
    for r in carried:  # the node's results are the stage's (boxes as float32)
        want = done[r["sequence"]]
        assert len(r["detections"]) == min(len(want), 64)
    with Device.open("imx219", realtime=False) as cam, pytest.raises(ConfigError, match="in-sensor network"):
        next(cam.stream(frames=1, metadata=True))
