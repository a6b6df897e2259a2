"""The LD_PRELOAD library that gives unmodified programs emulated ``/dev/videoN`` nodes (``rollcam run``).

``rollcam_preload.c`` is built into ``librollcam_preload.so`` beside this file by the normal install (a
setuptools build step, on a machine with a C compiler). It forwards the program's libc
calls on the device paths to ``rollcam.emu.v4l2.server``; ``environment`` is what a program needs to use it.
The two speak the wire format of ``rollcam_wire.h`` (``wire`` reads it for the server).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from pathlib import Path

from rollcam.common.errors import DeviceError

LIBRARY_NAME = "librollcam_preload.so"
ENV_SOCKET = "ROLLCAM_PRELOAD_SOCKET"
ENV_DEVICES = "ROLLCAM_PRELOAD_DEVICES"
ENV_DEBUG = "ROLLCAM_PRELOAD_DEBUG"
ENV_SYSFS = "ROLLCAM_PRELOAD_SYSFS"
VIDEO_MAJOR = 81


def library_path() -> Path:
    """The built library; DeviceError (naming the fix) when the install did not build it."""
    path = Path(__file__).with_name(LIBRARY_NAME)
    if not path.is_file():
        raise DeviceError(f"{path} is missing: the install builds the preload library; reinstall rollcam on a "
                          "machine with a C compiler")
    return path


def write_sysfs(root: Path, nodes: Iterable[tuple[str, int, str]]) -> None:
    """The /sys entries tools read about a video node, as files under ``root`` (the library shows them at
    /sys/dev/char/81:N and /sys/class/video4linux/NAME): ``nodes`` are (path, minor, card name)."""
    for path, minor, card in nodes:
        name = Path(path).name
        uevent = f"MAJOR={VIDEO_MAJOR}\nMINOR={minor}\nDEVNAME={name}\n"
        char = root / "dev" / "char" / f"{VIDEO_MAJOR}:{minor}"
        cls = root / "class" / "video4linux" / name
        for folder in (char, cls):
            folder.mkdir(parents=True, exist_ok=True)
            (folder / "uevent").write_text(uevent)
            (folder / "dev").write_text(f"{VIDEO_MAJOR}:{minor}\n")
            (folder / "name").write_text(card + "\n")
            (folder / "index").write_text("0\n")


def environment(socket_path: str, devices: Iterable[str], base: Mapping[str, str] | None = None,
                sysfs: Path | None = None) -> dict[str, str]:
    """``base`` (default: this process's environment) with the library preloaded for ``devices`` (and the
    /sys mirror ``write_sysfs`` made, if any)."""
    env = dict(os.environ if base is None else base)
    preload = [str(library_path()), *[p for p in env.get("LD_PRELOAD", "").split() if p]]
    env["LD_PRELOAD"] = " ".join(preload)
    env[ENV_SOCKET] = socket_path
    env[ENV_DEVICES] = ",".join(devices)
    if sysfs is not None:
        env[ENV_SYSFS] = str(sysfs)
    return env
