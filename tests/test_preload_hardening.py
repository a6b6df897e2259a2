"""``rollcam run``'s library and server under abuse: bad buffers, racing threads, forks, bad pointers, protocol
violations, mismatched builds and killed runs (issue 37's R2, R4, R5, R6, R11, R13 and the wire format; issue
36's sign-extended ioctl request). The sanitizer and fuzz runs are in test_preload_sanitizers.py (slow)."""

from __future__ import annotations

import ctypes
import errno
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from helpers import wait_for
from programs import compile_c, python_under, run_under
from rollcam.emu.preload import LIBRARY_NAME, wire
from rollcam.host.servers.devnodes import FOLDER_PREFIX, program_environment, reclaim_stale_folders, serving

LIB = Path(__file__).resolve().parents[1] / "emu" / "preload" / LIBRARY_NAME
PRELOAD_SOURCE = LIB.with_name("rollcam_preload.c")
PROGRAMS = Path(__file__).with_name("preload_programs")
pytestmark = pytest.mark.skipif(not LIB.is_file(), reason=f"{LIB} not built (pip install -e . with a C compiler)")

SOURCE = "emu:imx219?size=320x240&format=YUYV"


@pytest.fixture(scope="module")
def server():
    with serving([("/dev/video0", SOURCE), ("/dev/video1", "emu:ov9281?size=640x400")]) as s:
        yield s


def open_fds() -> int:
    return len(os.listdir("/proc/self/fd"))


PRELUDE = """
    import ctypes, errno, fcntl, json, mmap, os
    from rollcam.emu.v4l2 import abi
    R = {k: v[0] for k, v in abi.REQUESTS.items()}
    libc = ctypes.CDLL(None, use_errno=True)
    libc.ioctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_void_p]

    def raw_ioctl(fd, request, pointer):
        if libc.ioctl(fd, request, pointer) < 0:
            return errno.errorcode[ctypes.get_errno()]
        return "ok"

    def stream(fd, count=2):
        fcntl.ioctl(fd, R["REQBUFS"], abi.RequestBuffers(count=count, type=1, memory=1))
        for i in range(count):
            fcntl.ioctl(fd, R["QBUF"], abi.Buffer(index=i, type=1, memory=1))
        fcntl.ioctl(fd, R["STREAMON"], ctypes.c_int(1))
"""


def probe(server, code: str, timeout: float = 120) -> dict:
    return python_under(server, textwrap.dedent(PRELUDE) + textwrap.dedent(code), timeout=timeout)


# ---------------------------------------------------------------------------------------- the wire format
def test_the_library_is_built_with_the_wire_format_the_server_reads():
    """One definition (rollcam_wire.h): the built library reports what it was compiled with, and it is what
    the Python side parsed."""
    lib = ctypes.CDLL(str(LIB))
    out = (ctypes.c_int64 * 32)()
    n = lib.rollcam_preload_wire(out, 32)
    ops = [wire.Op[name] for name in ("OPEN", "IOCTL", "MMAP", "READ", "POLL", "CLOSE", "ATTACH")]
    assert list(out[:n]) == [wire.MAGIC, wire.VERSION, wire.MAX_PAYLOAD, wire.MAX_FDS, wire.HELLO.size,
                             wire.REQ.size, wire.RSP.size, 8, 8, *ops]
    assert len(wire.Op) == len(ops)


def test_a_library_from_another_build_gets_a_clear_line_not_garbage(server, tmp_path, caplog):
    """A library speaking wire format 99 is refused at the hello: the program's open() fails with ENODEV and
    both sides say which versions met."""
    header = (PRELOAD_SOURCE.parent / "rollcam_wire.h").read_text()
    (tmp_path / "rollcam_wire.h").write_text(header.replace(f"ROLLCAM_WIRE_VERSION {wire.VERSION}",
                                                            "ROLLCAM_WIRE_VERSION 99"))
    shutil.copy(PRELOAD_SOURCE, tmp_path / "rollcam_preload.c")
    other = compile_c(tmp_path / "other.so", "-shared", "-fPIC", "-O1", str(tmp_path / "rollcam_preload.c"),
                      "-ldl", "-lpthread")
    env = program_environment(server)
    env["LD_PRELOAD"] = str(other)
    code = ("import errno, os\ntry:\n os.open('/dev/video0', os.O_RDWR)\n"
            "except OSError as e:\n print(errno.errorcode[e.errno])")
    with caplog.at_level("WARNING", logger="rollcam.emu.v4l2.server"):
        p = run_under(server, sys.executable, "-c", code, env=env)
    assert p.stdout.strip() == "ENODEV"
    assert f"speaks wire format {wire.VERSION}" in p.stderr and "this library 99" in p.stderr
    assert "reinstall rollcam" in p.stderr
    assert any("wire format 99" in r.getMessage() for r in caplog.records)


# --------------------------------------------------------------------------------- R4: sealed buffers
def test_a_program_cannot_truncate_an_exported_buffer_and_the_devices_stream_on():
    """R4: ftruncate of an EXPBUF'd memfd fails (EPERM: sealed) instead of the server dying of SIGBUS at the
    next fill and taking every device with it. Runs under `rollcam run` in a child, so a crash shows as its
    status rather than killing the test process."""
    code = textwrap.dedent(PRELUDE) + textwrap.dedent("""
        out = {}
        fd = os.open("/dev/video0", os.O_RDWR)
        fcntl.ioctl(fd, R["REQBUFS"], abi.RequestBuffers(count=2, type=1, memory=1))
        exp = abi.ExportBuffer(type=1, index=0)
        fcntl.ioctl(fd, R["EXPBUF"], exp)
        for size in (0, 1 << 30):
            try:
                os.ftruncate(exp.fd, size)
                out[str(size)] = "ok"
            except OSError as e:
                out[str(size)] = errno.errorcode[e.errno]
        for i in range(2):
            fcntl.ioctl(fd, R["QBUF"], abi.Buffer(index=i, type=1, memory=1))
        fcntl.ioctl(fd, R["STREAMON"], ctypes.c_int(1))
        seqs = []
        for _ in range(4):  # the pump fills buffer 0 (the exported one) again and again
            b = abi.Buffer(type=1, memory=1)
            fcntl.ioctl(fd, R["DQBUF"], b)
            seqs.append(b.sequence)
            fcntl.ioctl(fd, R["QBUF"], abi.Buffer(index=b.index, type=1, memory=1))
        os.close(exp.fd)
        os.close(fd)
        other = os.open("/dev/video1", os.O_RDWR)
        stream(other)
        b = abi.Buffer(type=1, memory=1)
        fcntl.ioctl(other, R["DQBUF"], b)
        out["other"] = b.bytesused
        out["seqs"] = seqs
        print(json.dumps(out))
    """)
    p = subprocess.run([sys.executable, "-m", "rollcam.host.cli", "run", "--device", f"/dev/video0={SOURCE}",
                        "--device", "/dev/video1=emu:ov9281?size=640x400", "--", sys.executable, "-c", code],
                       capture_output=True, text=True, timeout=180)
    assert p.returncode == 0, p.stderr[-3000:]
    r = json.loads(p.stdout.strip().splitlines()[-1])
    assert r["0"] == "EPERM" and r["1073741824"] == "EPERM"
    assert len(r["seqs"]) == 4 and r["other"] >= 640 * 400


# -------------------------------------------------------------------------------- R5: handle lifetime
def test_threads_racing_close_dup_open_and_ioctl_on_one_fd_are_safe(server, tmp_path):
    """R5: 8 threads racing close/dup/dup2/open/ioctl/poll on one fd, closes under a blocked DQBUF, a fork
    and an open/close storm: no crash, no hang, only the errors Linux allows; every file released after."""
    stress = compile_c(tmp_path / "stress", "-O1", "-g", "-pthread", str(PROGRAMS / "stress.c"))
    before = open_fds()
    p = run_under(server, str(stress), "/dev/video0", "2", timeout=180)
    r = json.loads(p.stdout.strip().splitlines()[-1])
    assert r["unexpected"] == 0 and r["fork_failed"] == 0 and r["calls"] > 100
    wait_for(lambda: server.open_files() == 0, what="every file released")
    wait_for(lambda: open_fds() <= before, what="the server's descriptors back to before")


def test_when_the_server_dies_a_blocked_dqbuf_and_later_calls_fail_with_enodev(tmp_path):
    """R5: the server going away mid-DQBUF wakes the waiting thread with ENODEV, and every later call on
    the file fails with ENODEV (not an undefined errno, not a hang)."""
    code = textwrap.dedent(PRELUDE) + textwrap.dedent("""
        import sys
        fd = os.open("/dev/video0", os.O_RDWR)
        fcntl.ioctl(fd, R["REQBUFS"], abi.RequestBuffers(count=2, type=1, memory=1))
        fcntl.ioctl(fd, R["QBUF"], abi.Buffer(index=0, type=1, memory=1))
        fcntl.ioctl(fd, R["STREAMON"], ctypes.c_int(1))
        fcntl.ioctl(fd, R["DQBUF"], abi.Buffer(type=1, memory=1))
        print("waiting", flush=True)
        b = abi.Buffer(type=1, memory=1)
        out = [raw_ioctl(fd, R["DQBUF"], ctypes.addressof(b))]  # nothing queued: blocks until the server goes
        out.append(raw_ioctl(fd, R["QUERYCAP"], ctypes.addressof(abi.Capability())))
        os.close(fd)
        print(json.dumps(out))
    """)
    with serving([("/dev/video0", SOURCE)]) as s:
        p = subprocess.Popen([sys.executable, "-c", code], env=program_environment(s), stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
        assert p.stdout.readline().strip() == "waiting", p.stderr.read()
    out, err = p.communicate(timeout=60)
    assert p.returncode == 0, err[-2000:]
    assert json.loads(out.strip().splitlines()[-1]) == ["ENODEV", "ENODEV"]


# ------------------------------------------------------------------------------- R2: bad pointers
def test_garbage_pointers_get_efault_as_on_linux_not_sigsegv(server):
    """R2: a bad argument pointer is EFAULT (ioctl in and out, the extended-control array, read()'s buffer,
    poll's array), and the file goes on working."""
    r = probe(server, """
        out = {}
        fd = os.open("/dev/video0", os.O_RDWR | os.O_NONBLOCK)
        out["querycap_null"] = raw_ioctl(fd, R["QUERYCAP"], None)
        out["querycap_garbage"] = raw_ioctl(fd, R["QUERYCAP"], 0x10)
        out["s_fmt_garbage"] = raw_ioctl(fd, R["S_FMT"], 0xdead0000)
        bad_ctrls = abi.ExtControls(which=0x00980000, count=2)
        bad_ctrls.controls = 0x18
        out["ext_ctrls_array"] = raw_ioctl(fd, R["G_EXT_CTRLS"], ctypes.addressof(bad_ctrls))
        libc.read.argtypes = [ctypes.c_int, ctypes.c_void_p, ctypes.c_size_t]
        libc.poll.argtypes = [ctypes.c_void_p, ctypes.c_ulong, ctypes.c_int]
        os.set_blocking(fd, True)
        n = libc.read(fd, 0x20, 4096)  # starts read() I/O; the frame cannot land at 0x20
        out["read"] = errno.errorcode[ctypes.get_errno()] if n < 0 else n
        n = libc.poll(0x30, 1, 0)
        out["poll"] = errno.errorcode[ctypes.get_errno()] if n < 0 else n
        cap = abi.Capability()
        fcntl.ioctl(fd, R["QUERYCAP"], cap)
        out["after"] = cap.card
        print(json.dumps(out))
    """)
    assert r == {"querycap_null": "EFAULT", "querycap_garbage": "EFAULT", "s_fmt_garbage": "EFAULT",
                 "ext_ctrls_array": "EFAULT", "read": "EFAULT", "poll": "EFAULT",
                 "after": "rollcam imx219 emulator"}


def test_an_ioctl_on_read_only_memory_is_efault_after_the_driver_ran(server):
    """R2: _IOR into memory the program may not write: the call runs and the copy out fails (EFAULT), as in
    video_usercopy."""
    r = probe(server, """
        libc.mmap.restype = ctypes.c_void_p
        libc.mmap.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int, ctypes.c_int, ctypes.c_int,
                              ctypes.c_long]
        page = libc.mmap(None, 4096, mmap.PROT_READ, mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS, -1, 0)
        fd = os.open("/dev/video0", os.O_RDWR)
        print(json.dumps({"ro": raw_ioctl(fd, R["QUERYCAP"], page), "g_fmt": raw_ioctl(fd, R["G_FMT"], page)}))
    """)
    assert r == {"ro": "EFAULT", "g_fmt": "EINVAL"}  # G_FMT of type 0 (the zero page) fails before any copy out


# ----------------------------------------------------------------- issue 36: sign-extended requests
def test_a_sign_extended_dqbuf_request_blocks_like_the_kernel_not_eagain(server):
    """Issue 36: the `motion` daemon passes requests through an int, so VIDIOC_DQBUF (0xc0585611) arrives
    as 0xffffffffc0585611. The kernel compares 32 bits: a blocking DQBUF waits for a frame."""
    r = probe(server, """
        fd = os.open("/dev/video0", os.O_RDWR)
        stream(fd)
        out = []
        for _ in range(3):
            b = abi.Buffer(type=1, memory=1)
            res = raw_ioctl(fd, R["DQBUF"] | 0xFFFFFFFF00000000, ctypes.addressof(b))
            out.append([res, b.bytesused])
            if res == "ok":
                fcntl.ioctl(fd, R["QBUF"], abi.Buffer(index=b.index, type=1, memory=1))
        cap = abi.Capability()
        out.append(raw_ioctl(fd, R["QUERYCAP"] | 0xFFFFFFFF00000000, ctypes.addressof(cap)))
        print(json.dumps(out))
    """)
    assert r == [["ok", 320 * 240 * 2]] * 3 + ["ok"]


# --------------------------------------------------------------------------------------- R6: fork
def test_a_forked_child_shares_the_open_file_as_on_linux(server):
    """R6: the child's ioctls act on the parent's open file (its STREAMOFF stops the parent's stream), each
    process has its own connection, and the file stays open until the last process closes it."""
    r = probe(server, """
        import sys
        fd = os.open("/dev/video0", os.O_RDWR)
        stream(fd)
        go_r, go_w = os.pipe()
        pid = os.fork()
        if pid == 0:
            os.read(go_r, 1)  # the parent has closed its fd by now
            cap = abi.Capability()
            ok = raw_ioctl(fd, R["QUERYCAP"], ctypes.addressof(cap)) == "ok"
            b = abi.Buffer(type=1, memory=1)
            ok = ok and raw_ioctl(fd, R["DQBUF"], ctypes.addressof(b)) == "ok"  # the parent's stream, still on
            ok = ok and raw_ioctl(fd, R["STREAMOFF"], ctypes.addressof(ctypes.c_int(1))) == "ok"
            os._exit(0 if ok else 3)
        b = abi.Buffer(type=1, memory=1)
        fcntl.ioctl(fd, R["DQBUF"], b)
        os.close(fd)
        os.write(go_w, b"x")
        _, status = os.waitpid(pid, 0)
        print(json.dumps({"child": os.waitstatus_to_exitcode(status)}))
    """)
    assert r == {"child": 0}
    node = server.nodes["/dev/video0"]
    wait_for(lambda: server.open_files() == 0 and node.owner is None, what="the shared file released")
    assert not node.driver.queue.streaming


# --------------------------------------------------------------------- R11: one file per connection
def _connect(path: str) -> socket.socket:
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.connect(path)
    s.sendall(wire.HELLO.pack(wire.MAGIC, wire.VERSION))
    assert wire.HELLO.unpack(s.recv(wire.HELLO.size, socket.MSG_WAITALL)) == (wire.MAGIC, wire.VERSION)
    return s


def _request(s: socket.socket, op: int, payload: bytes = b"", a: int = 0) -> tuple[int, int, list[int]]:
    s.sendall(wire.REQ.pack(op, len(payload), a, 0, 0) + payload)
    data, anc, _, _ = s.recvmsg(wire.RSP.size, socket.CMSG_SPACE(8 * 4))
    fds = []
    for level, kind, blob in anc:
        if (level, kind) == (socket.SOL_SOCKET, socket.SCM_RIGHTS):
            fds += list(memoryview(blob).cast("i"))
    result, err, length = wire.RSP.unpack(data)
    if length:
        s.recv(length, socket.MSG_WAITALL)
    return result, err, fds


def test_a_second_open_on_one_connection_is_refused_and_leaks_nothing(server):
    """R11: 200 connections that each OPEN twice: the second is refused (EPROTO), each first file is
    released with its connection, no EBUSY is left behind, the server's descriptors stay flat."""
    node = server.nodes["/dev/video0"]
    before = open_fds()
    for _ in range(200):
        with _connect(server.socket_path) as s:
            _, err1, fds = _request(s, wire.Op.OPEN, b"/dev/video0", os.O_RDWR)
            _, err2, more = _request(s, wire.Op.OPEN, b"/dev/video0", os.O_RDWR)
            for fd in fds + more:
                os.close(fd)
            assert (err1, err2) == (0, errno.EPROTO)
    wait_for(lambda: server.open_files() == 0 and not node.files, what="every file released")
    assert open_fds() <= before + 2
    r = probe(server, """
        fd = os.open("/dev/video0", os.O_RDWR)
        stream(fd)
        print(json.dumps("streaming"))
    """)
    assert r == "streaming"


# ----------------------------------------------------------------------------- R13: the run's folder
def test_a_killed_run_leaves_its_folder_to_the_next_run(tmp_path):
    """R13: `kill -9` of `rollcam run` leaves rollcam-run-PID-*; the next run removes it (its process is
    gone and nothing listens on its socket) and keeps a live run's folder."""
    env = dict(os.environ, TMPDIR=str(tmp_path))
    victim = subprocess.Popen([sys.executable, "-m", "rollcam.host.cli", "run", "--", "sleep", "60"], env=env)
    try:
        wait_for(lambda: any((f / "v4l2.sock").exists() for f in tmp_path.glob(f"{FOLDER_PREFIX}*")),
                 timeout_s=60, what="the run's socket")
        victim.send_signal(signal.SIGKILL)
        victim.wait(30)
    finally:
        if victim.poll() is None:
            victim.kill()
    [left] = list(tmp_path.glob(f"{FOLDER_PREFIX}*"))
    mine = tmp_path / f"{FOLDER_PREFIX}{os.getpid()}-live"
    mine.mkdir()
    p = subprocess.run([sys.executable, "-m", "rollcam.host.cli", "run", "--", "true"], env=env, timeout=120)
    assert p.returncode == 0
    assert not left.exists() and mine.is_dir()
    assert reclaim_stale_folders(tmp_path) == [] and mine.is_dir()


class _BrokenNode:
    """A device node whose open() has a bug (raises what no request should): the server's own fault."""

    def __init__(self) -> None:
        self.closed = False

    def open(self, flags: int):
        raise RuntimeError("a bug in open")

    def close(self) -> None:
        self.closed = True


def test_a_connection_thread_that_breaks_is_joined_and_its_error_raised_on_close(tmp_path):
    """A fault of the server's own in one connection ends that connection, the server keeps serving the others,
    and close() joins every thread and raises the fault (it was a traceback on stderr, lost to the caller)."""
    from rollcam.common.errors import DeviceError
    from rollcam.emu.v4l2.server import PreloadServer

    node = _BrokenNode()
    server = PreloadServer({"/dev/video0": node}, str(tmp_path / "s"))
    with _connect(server.socket_path) as s:
        s.sendall(wire.REQ.pack(wire.Op.OPEN, len(b"/dev/video0"), os.O_RDWR, 0, 0) + b"/dev/video0")
        assert s.recv(wire.RSP.size) == b""  # the connection ends
    with _connect(server.socket_path):  # the next one is served
        pass
    with pytest.raises(DeviceError, match="rollcam-preload-conn failed: RuntimeError"):
        server.close()
    assert node.closed and not (tmp_path / "s").exists()
