"""``rollcam run``'s work: serve emulated ``/dev/videoN`` nodes and run a program that sees them.

Each device is a ``FirmwareCamera`` (from an ``emu:`` URI or a sensor name) behind an ``EmuDriver`` and a
``DeviceNode``, and, when its camera runs an in-sensor network, a metadata node (``MetaDriver``) at the next
free ``/dev/videoN``; one ``PreloadServer`` serves them on a Unix socket in a private temporary folder
(``rollcam-run-PID-*``: a folder a killed run left behind is removed by the next run). The
program runs with the preload library (``rollcam.emu.preload``) in ``LD_PRELOAD``, the socket and device
paths in its environment, and ``rollcam/host/shims`` first on its ``PYTHONPATH`` (stand-in modules such as
``picamera2``). Its exit status is returned (128 + N when signal N ended it); the socket and folder go.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import stat
import subprocess
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from rollcam.common.errors import ConfigError
from rollcam.common.faults import FaultPlan
from rollcam.emu.preload import environment, write_sysfs
from rollcam.emu.v4l2.driver import EmuDriver
from rollcam.emu.v4l2.meta import MetaDriver
from rollcam.emu.v4l2.node import DeviceNode
from rollcam.emu.v4l2.server import PreloadServer
from rollcam.firmware.camera import FirmwareCamera
from rollcam.firmware.rig import LiveRig
from rollcam.host.servers.standins import standin_env

DEFAULT_DEVICE = "/dev/video0"
DEFAULT_SOURCE = "emu:imx219?size=640x480"
FOLDER_PREFIX = "rollcam-run-"
"""A run's private folder is ``FOLDER_PREFIX`` + its pid + ``-`` + a random part (so a later run can tell an
abandoned one: ``reclaim_stale_folders``)."""


def parse_device(text: str, index: int) -> tuple[str, str]:
    """``PATH=SOURCE`` or ``SOURCE`` (then ``/dev/video{index}``) -> (path, source)."""
    path, sep, source = text.partition("=")
    if not sep or not path.startswith("/"):
        path, source = f"/dev/video{index}", text
    if not source:
        raise ConfigError(f"device {text!r}: expected PATH=SOURCE (an emu: URI or a sensor name)")
    return path, source


def build_camera(source: str, rigs: dict[Any, LiveRig] | None = None) -> tuple[FirmwareCamera, FaultPlan]:
    """The camera an ``emu:`` URI or a sensor name describes, on the real device clock, and the URI's
    ``faults=`` plan (``rollcam.common.faults``; none for a sensor name). With ``rig=`` (docs/rigs.md) it is
    camera ``rig_cam`` of a ``LiveRig`` on its own clock, the rig shared through ``rigs`` by every device that
    names the same camera options and rig."""
    from rollcam.host.sources.emu import rig_device_spec

    spec, plan, choice = rig_device_spec(source, ConfigError)
    if choice is None:
        return FirmwareCamera(spec), plan
    rigs = {} if rigs is None else rigs
    rig = rigs.get((spec, choice[0]))
    if rig is None:
        rig = rigs[(spec, choice[0])] = LiveRig(choice[0], spec)
        rig.start_trigger()
    return rig.cameras[choice[1]], plan


def _next_free(path: str, taken: set[str]) -> str:
    """The first ``/dev/videoK`` after ``path``'s number that no device takes (``/dev/video0`` -> video1)."""
    digits = len(path) - len(path.rstrip("0123456789"))
    stem, n = (path[:-digits], int(path[-digits:])) if digits else (path, -1)
    k = n + 1
    while f"{stem}{k}" in taken:
        k += 1
    return f"{stem}{k}"


def minor_of(path: str, index: int) -> int:
    """The minor number a node reports: the digits ending its path (video2 -> 2), else its index."""
    digits = len(path) - len(path.rstrip("0123456789"))
    return int(path[-digits:]) if digits else index


def _abandoned(folder: Path, pid: int) -> bool:
    """Whether a run's folder outlived its process: no process ``pid`` here and nothing listening on its
    socket (both, so that a run in another PID namespace sharing /tmp keeps its folder)."""
    try:
        os.kill(pid, 0)
        return False
    except ProcessLookupError:
        pass
    except PermissionError:
        return False
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        try:
            s.connect(str(folder / "v4l2.sock"))
            return False
        except OSError:
            return True


def reclaim_stale_folders(root: Path | None = None) -> list[Path]:
    """Remove the folders of runs that ended without cleaning up (``kill -9`` of ``rollcam run``): this
    user's ``rollcam-run-PID-*`` folders in ``root`` (default: the temporary folder) whose process is gone.
    Returns what was removed."""
    root = Path(tempfile.gettempdir()) if root is None else root
    removed = []
    for folder in root.glob(f"{FOLDER_PREFIX}*-*"):
        pid = folder.name[len(FOLDER_PREFIX):].partition("-")[0]
        try:
            st = folder.lstat()
        except OSError:
            continue
        if not pid.isdigit() or not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid():
            continue
        if _abandoned(folder, int(pid)):
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(folder)
    return removed


@contextlib.contextmanager
def serving(devices: Sequence[tuple[str, str]], *, realtime: bool = True) -> Iterator[PreloadServer]:
    """Serve ``(path, source)`` devices on a socket in a new private folder; everything goes on exit."""
    paths = [p for p, _ in devices]
    if len(set(paths)) != len(paths):
        raise ConfigError(f"device paths {paths!r} repeat")
    reclaim_stale_folders()
    folder = tempfile.mkdtemp(prefix=f"{FOLDER_PREFIX}{os.getpid()}-")
    nodes: dict[str, DeviceNode] = {}
    rigs: dict[Any, LiveRig] = {}
    try:
        for i, (path, source) in enumerate(devices):
            camera, faults = build_camera(source, rigs)
            if any(camera is n.driver.camera for n in nodes.values()):
                raise ConfigError(f"device {path}: {source!r} is a rig camera another device already serves")
            nodes[path] = DeviceNode(EmuDriver(camera, realtime=realtime, faults=faults), path, minor_of(path, i))
        for path, node in list(nodes.items()):
            if node.driver.camera.spec.insensor is not None:  # its results on a metadata node, as uvcvideo's
                meta_path = _next_free(path, set(nodes) | set(paths))
                meta = DeviceNode(MetaDriver(node.driver), meta_path, minor_of(meta_path, len(nodes)))
                meta.bus_minor = node.minor
                nodes[meta_path] = meta
        server = PreloadServer(nodes, os.path.join(folder, "v4l2.sock"))
        write_sysfs(Path(folder) / "sys", [(n.path, n.minor, f"rollcam {n.driver.camera.sensor.name} emulator")
                                           for n in nodes.values()])
    except BaseException:
        for node in nodes.values():
            node.close()
        for rig in rigs.values():
            rig.close()
        shutil.rmtree(folder, ignore_errors=True)
        raise
    try:
        yield server
    finally:
        server.close()
        for rig in rigs.values():
            rig.close()
        shutil.rmtree(folder, ignore_errors=True)


def program_environment(server: PreloadServer, base: dict[str, str] | None = None,
                        sources: Sequence[str] = ()) -> dict[str, str]:
    """The environment a program under ``rollcam run`` gets: the preload library and its socket, and the
    stand-in modules (``picamera2``) first on ``PYTHONPATH`` (``rollcam.host.servers.standins``), their cameras the
    same ``sources`` as the devices (``Picamera2(0)`` is the first ``--device``)."""
    env = environment(server.socket_path, list(server.nodes), base, Path(server.socket_path).with_name("sys"))
    return standin_env(sources, env=env)


def run_program(devices: Sequence[tuple[str, str]], argv: Sequence[str], *, realtime: bool = True) -> int:
    """Run ``argv`` with the devices; its exit status (128 + N after signal N)."""
    if not argv:
        raise ConfigError("no program to run (rollcam run [--device PATH=SOURCE ...] -- PROGRAM ARGS...)")
    if shutil.which(argv[0]) is None:
        raise ConfigError(f"program {argv[0]!r} not found")
    with serving(devices, realtime=realtime) as server:
        proc = subprocess.Popen(list(argv), env=program_environment(server, sources=[src for _, src in devices]))
        forwarded = {s: signal.signal(s, lambda n, _f: proc.send_signal(n)) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            code = proc.wait()
        finally:
            for s, old in forwarded.items():
                signal.signal(s, old)
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    return 128 - code if code < 0 else code
