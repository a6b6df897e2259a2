"""The emulated camera as a PipeWire ``Video/Source`` node, read by any PipeWire client (GStreamer's pipewiresrc,
``pw-cat``, ``pw-dump``; browsers and desktop apps through the camera portal).

How: a PipeWire daemon runs under ``rollcam run``'s preload (``rollcam.host.servers.devnodes``), so PipeWire's own V4L2
source (``api.v4l2.source``, the node WirePlumber makes for a real webcam) opens rollcam's emulated ``/dev/video0``
and streams it: the node's formats, sizes and frame rate are what the emulated V4L2 device offers, and the frames
are its frames, byte for byte. The daemon is private and headless: its own runtime folder (``XDG_RUNTIME_DIR``),
no login session, and WirePlumber (the session manager that links a client's stream to the node it names) on a
private D-Bus (``dbus-run-session``), since WirePlumber 0.4 will not start without one.

Needs Debian's ``pipewire``, ``pipewire-bin``, ``wireplumber`` and ``dbus-daemon`` (clients: ``gstreamer1.0-pipewire``).
Not tried yet: publishing into a desktop's running PipeWire (docs/labs.md says what is left).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import time
from pathlib import Path
from typing import Any

from rollcam.common.errors import ConfigError, DeviceError
from rollcam.common.lifecycle import Closeable, Deadline

from ..sources.emu import device_spec
from .devnodes import program_environment, serving

PROGRAMS = ("pipewire", "wireplumber", "dbus-run-session", "pw-cli", "pw-dump")
"""The programs a PipeWire camera runs (Debian: pipewire, pipewire-bin, wireplumber, dbus-daemon)."""

DEVICE = "/dev/video0"
"""The emulated device PipeWire's V4L2 source opens, inside the daemon's preload."""


def pw_objects(env: dict[str, str], timeout_s: float = 10) -> list[dict[str, Any]]:
    """Every object of the PipeWire instance that ``env`` names, as ``pw-dump`` prints them."""
    p = subprocess.run(["pw-dump"], env=env, capture_output=True, text=True, timeout=timeout_s, check=False)
    if p.returncode != 0:
        raise DeviceError(f"pw-dump failed ({p.returncode}): {p.stderr.strip()[-300:]}")
    return json.loads(p.stdout or "[]")


def find_node(objects: list[dict[str, Any]], name: str) -> dict[str, Any] | None:
    """The node called ``name`` among ``pw-dump`` objects, or None."""
    for obj in objects:
        if obj.get("type", "").endswith(":Node") and obj.get("info", {}).get("props", {}).get("node.name") == name:
            return obj
    return None


class PipeWireCamera(Closeable):
    """A private, headless PipeWire (with WirePlumber) in ``runtime_dir`` publishing ``source`` (a sensor name or
    an ``emu:`` URI) as the ``Video/Source`` node ``name``. ``env`` is the environment a client needs to see it.
    A context manager; ``close()`` stops the daemons and the emulated device."""

    closed_error = DeviceError

    def __init__(self, source: str, runtime_dir: str | os.PathLike[str], *, name: str = "rollcam",
                 description: str | None = None, timeout_s: float = 30) -> None:
        missing = [p for p in PROGRAMS if shutil.which(p) is None]
        if missing:
            raise ConfigError(f"a PipeWire camera needs {missing} (Debian: pipewire pipewire-bin wireplumber "
                              f"dbus-daemon)")
        if not name or any(c.isspace() or c in "=,\"'" for c in name):
            raise ConfigError(f"PipeWire node name {name!r}: give a word without spaces, quotes, '=' or ','")
        spec, _ = device_spec(source, ConfigError)
        self.source, self.name = source, name
        self.description = description or f"rollcam {spec.sensor.name}"
        self.runtime_dir = Path(runtime_dir)
        self.runtime_dir.mkdir(mode=0o700, parents=True, exist_ok=True)
        base = {k: v for k, v in os.environ.items() if k not in ("DBUS_SESSION_BUS_ADDRESS", "PIPEWIRE_REMOTE")}
        self.env = {**base, "XDG_RUNTIME_DIR": str(self.runtime_dir)}
        self._stack = contextlib.ExitStack()
        self._procs: list[subprocess.Popen] = []
        try:
            self._start(timeout_s)
        except BaseException:
            self.close()
            raise

    def _spawn(self, argv: list[str], env: dict[str, str], log: str) -> subprocess.Popen:
        out = self._stack.enter_context((self.runtime_dir / log).open("w"))
        # a group of its own: dbus-run-session's bus daemon and WirePlumber go with it
        proc = subprocess.Popen(argv, env=env, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)
        self._procs.append(proc)
        return proc

    def _wait(self, what: str, ready: Any, deadline: Deadline) -> Any:
        while True:
            for proc in self._procs:
                if proc.poll() is not None:
                    raise DeviceError(f"{proc.args[0]} exited ({proc.returncode}) before {what}; its log is in "
                                      f"{self.runtime_dir}")
            got = ready()
            if got:
                return got
            if deadline.expired:
                raise DeviceError(f"PipeWire camera {self.name!r}: no {what} after {deadline}")
            time.sleep(0.05)  # polling a process we do not control: pw-dump and a socket file have no event

    def _start(self, timeout_s: float) -> None:
        deadline = Deadline(timeout_s)
        server = self._stack.enter_context(serving([(DEVICE, self.source)]))
        socket = self.runtime_dir / "pipewire-0"
        self._spawn(["pipewire"], program_environment(server, self.env), "pipewire.log")
        self._wait("PipeWire socket", socket.exists, deadline)
        self._spawn(["dbus-run-session", "--", "wireplumber"], self.env, "wireplumber.log")
        self._wait("WirePlumber client", lambda: any(
            o.get("info", {}).get("props", {}).get("application.name") == "WirePlumber"
            for o in pw_objects(self.env)), deadline)
        props = {"factory.name": "api.v4l2.source", "api.v4l2.path": DEVICE, "node.name": self.name,
                 "node.description": self.description, "media.class": "Video/Source", "object.linger": "true"}
        spa_json = "{ " + " ".join(f"{k}={json.dumps(v)}" for k, v in props.items()) + " }"  # a description has spaces
        p = subprocess.run(["pw-cli", "create-node", "spa-node-factory", spa_json],
                           env=self.env, capture_output=True, text=True, timeout=deadline.within(10), check=False)
        if p.returncode != 0 or "Error" in p.stdout + p.stderr:
            raise DeviceError(f"pw-cli create-node failed: {(p.stdout + p.stderr).strip()[-300:]}")
        self._wait(f"node {self.name!r}", lambda: find_node(pw_objects(self.env), self.name), deadline)

    def node(self) -> dict[str, Any]:
        """The camera's node as ``pw-dump`` shows it (properties, formats, state)."""
        self._check_open()
        node = find_node(pw_objects(self.env), self.name)
        if node is None:
            raise DeviceError(f"PipeWire node {self.name!r} is gone")
        return node

    def _close(self) -> None:
        for proc in reversed(self._procs):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGTERM)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        self._stack.close()

    def _describe(self) -> str:
        return f"PipeWire camera {self.name!r}"


__all__ = ["DEVICE", "PROGRAMS", "PipeWireCamera", "find_node", "pw_objects"]
