"""A real Linux kernel for the tests: Debian's stock kernel booted in QEMU, reached only through character devices.

The kernel tests put rollcam in front of the drivers that consume real cameras: vhci-hcd and uvcvideo (the
camera over USB/IP), usb_f_uvc on usbip-vudc (the camera as a USB gadget), vivid. What the guest is:

- **Kernel**: the image and the modules the tests need, from the Debian package that ``linux-image-amd64``
  depends on, extracted into a cache (``prepare()``; ``python tests/guest.py prepare`` from .ci/run), never
  installed into the machine's /boot.
- **Init**: a small initramfs (busybox-static, the modules, an init script) that loads the modules, mounts the
  host's root file system read-only over 9p as the guest's own (so the guest runs the host's usbip, v4l2-ctl,
  v4l2-compliance, socat and Python), a writable 9p exchange folder at ``/mnt``, and runs a command agent.
- **No network device.** The host talks to the guest through virtio-serial ports only: ``agent`` carries
  commands (the host writes a script into the exchange folder and its id on the port; the agent answers with
  the exit status), and ``usbip0``.. each carry one USB/IP connection from the guest's loopback to a rollcam
  server on the host (``UsbipBridge``). A guest-side close of a port reaches the host as QMP's
  ``VSERPORT_CHANGE`` event, which closes the bridged TCP connection, as a detach would.

KVM on these machines cannot boot a stock kernel (../shared/KERNEL.md): the guest runs under TCG, 15-35 s to a
shell. ``missing()`` names what a machine lacks, for the tests' skip message.
"""

from __future__ import annotations

import contextlib
import io
import itertools
import json
import os
import select
import shutil
import socket
import stat
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

KERNEL_META_PACKAGE = "linux-image-amd64"
CACHE = Path(os.environ.get("ROLLCAM_KERNEL_CACHE", Path.home() / ".cache" / "rollcam-kernel"))
BOOT_MODULES = ("virtio_pci", "virtio_console", "9p", "9pnet_virtio", "configfs", "vhci-hcd", "uvcvideo")
"""Modules the guest loads at boot (their dependencies come with them), in this order."""
EXTRA_MODULES = ("vivid", "usbip-vudc", "libcomposite", "usb_f_uvc")
"""Modules a test loads when it needs them (``Guest.load_module``)."""
LAYOUT = "2"  # of a cache folder; a folder of another layout is built again
BOOT_TIMEOUT_S = 240.0
OOPS_MARKERS = ("Oops:", "kernel BUG at", "BUG: ", "general protection fault", "Kernel panic",
                "refcount_t: underflow", "list_del corruption", "list_add corruption")
"""Console lines that say the guest kernel broke (an oops, a BUG, a corrupted list or refcount): a guest that
printed one can no longer be trusted to run the next test (``Guest.oops``)."""
USBIP_PORTS = 24  # virtio-serial ports for USB/IP connections, each used once (a port opens once at a time)
PROGRAMS = {"qemu-system-x86_64": "qemu-system-x86", "busybox": "busybox-static", "socat": "socat",
            "usbip": "usbip", "v4l2-ctl": "v4l-utils", "v4l2-compliance": "v4l-utils", "dpkg-deb": "dpkg"}
BUSYBOX = Path("/bin/busybox")


class GuestError(RuntimeError):
    """The guest did not boot, or a command in it failed or timed out (the message carries its output)."""


# ------------------------------------------------------------------------------------------------ kernel cache
def kernel_package() -> str:
    """The versioned kernel package the meta package depends on now (apt's view), e.g. linux-image-6.1.0-57-amd64."""
    out = subprocess.run(["apt-cache", "depends", KERNEL_META_PACKAGE], capture_output=True, text=True,
                         check=True).stdout
    for line in out.splitlines():
        name = line.strip().removeprefix("Depends:").strip()
        if line.strip().startswith("Depends:") and name.startswith("linux-image-"):
            return name
    raise GuestError(f"apt-cache knows no kernel that {KERNEL_META_PACKAGE} depends on (run apt-get update)")


def cached_kernel() -> Path | None:
    """The newest complete kernel in the cache, or None."""
    ready = sorted(p for p in CACHE.glob("linux-image-*/ready") if p.read_text().split()[-1:] == [LAYOUT])
    return ready[-1].parent if ready else None


def _module_order(moddir: Path, wanted: tuple[str, ...]) -> list[str]:
    """Module files (relative to ``moddir``) for ``wanted`` and their dependencies, each after what it needs."""
    deps: dict[str, list[str]] = {}
    for line in (moddir / "modules.dep").read_text().splitlines():
        path, _, needs = line.partition(":")
        deps[path] = needs.split()
    by_name = {Path(p).name.split(".ko")[0].replace("-", "_"): p for p in deps}
    builtin = {Path(p).name.split(".ko")[0].replace("-", "_")
               for p in (moddir / "modules.builtin").read_text().split()}
    order: list[str] = []

    def visit(path: str) -> None:
        if path in order:
            return
        for dep in deps[path]:  # each line lists all the module needs: visiting each first orders them
            visit(dep)
        order.append(path)

    for name in wanted:
        key = name.replace("-", "_")
        if key in builtin:
            continue
        if key not in by_name:
            raise GuestError(f"the kernel has no module {name!r}")
        visit(by_name[key])
    return order


def prepare() -> Path:
    """Download the current Debian kernel package and keep its image and the modules the tests need in the
    cache (whole or absent: built beside, then renamed). Returns the cache folder of that kernel."""
    package = kernel_package()
    target = CACHE / package
    if target == cached_kernel():
        return target
    CACHE.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=CACHE) as tmp:
        work = Path(tmp)
        subprocess.run(["apt-get", "download", package], cwd=work, check=True, capture_output=True)
        deb = next(work.glob("*.deb"))
        subprocess.run(["dpkg-deb", "-x", str(deb), str(work / "x")], check=True)
        boot = work / "x" / "boot"
        vmlinuz = next(boot.glob("vmlinuz-*"))
        version = vmlinuz.name.removeprefix("vmlinuz-")
        moddir = work / "x" / "lib" / "modules" / version
        # The package ships no modules.dep (its postinst runs depmod): busybox's depmod writes it.
        subprocess.run([str(BUSYBOX), "depmod", "-b", str(work / "x"), version], check=True)
        out = work / "kernel"
        (out / "modules").mkdir(parents=True)
        shutil.copy2(vmlinuz, out / "vmlinuz")
        orders = {name: [Path(rel).name for rel in _module_order(moddir, (name,))]
                  for name in BOOT_MODULES + EXTRA_MODULES}
        for rel in _module_order(moddir, BOOT_MODULES + EXTRA_MODULES):
            shutil.copy2(moddir / rel, out / "modules" / Path(rel).name)
        (out / "modules.json").write_text(json.dumps(orders, indent=1))
        (out / "version").write_text(version + "\n")
        (out / "ready").write_text(f"{package} layout {LAYOUT}\n")
        if target.exists():
            shutil.rmtree(target)
        (out).rename(target)
    return target


def missing() -> str | None:
    """What this machine lacks to boot the guest (the package to install, or the command that fills the
    kernel cache), or None."""
    for program, package in PROGRAMS.items():
        if shutil.which(program) is None:
            return f"{program} is not installed (Debian package {package})"
    if not BUSYBOX.is_file() or not _is_static(BUSYBOX):
        return f"{BUSYBOX} is not a static busybox (Debian package busybox-static)"
    if cached_kernel() is None:
        return f"no kernel in {CACHE}: run `python tests/guest.py prepare` (downloads {KERNEL_META_PACKAGE}'s kernel)"
    return None


def _is_static(path: Path) -> bool:
    """Whether an ELF program names no dynamic loader (busybox-static's does not; busybox's does)."""
    with open(path, "rb") as f:
        head = f.read(1 << 16)
    return b"/lib64/ld-linux" not in head


# ------------------------------------------------------------------------------------------------ initramfs
INIT = r"""#!/bin/busybox sh
/bin/busybox --install -s /bin
export PATH=/bin
mkdir -p /proc /sys /dev /host
mount -t proc proc /proc
mount -t sysfs sysfs /sys
mount -t devtmpfs dev /dev
for m in $(cat /modules.order); do insmod /modules/$m || echo "rollcam-guest: insmod $m failed" > /dev/console; done
mount -t 9p -o trans=virtio,version=9p2000.L,ro,msize=524288,cache=loose host /host || poweroff -f
mount -t proc proc /host/proc
mount -t sysfs sysfs /host/sys
mount -t devtmpfs dev /host/dev
mount -t configfs configfs /host/sys/kernel/config
mount -t tmpfs tmp /host/tmp
mount -t tmpfs run /host/run
mount -t 9p -o trans=virtio,version=9p2000.L,msize=524288 xchg /host/mnt || poweroff -f
mkdir -p /dev/virtio-ports
for p in /sys/class/virtio-ports/*; do ln -sf ../$(basename $p) /dev/virtio-ports/$(cat $p/name); done
ip link set lo up
echo "rollcam-guest: ready" > /dev/console
exec 3<>/dev/virtio-ports/agent
while read -r id <&3; do
  chroot /host /usr/bin/env PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin HOME=/tmp \
    /bin/sh -c "cd /mnt && exec /bin/sh /mnt/cmd/$id.sh" > /host/mnt/cmd/$id.out 2>&1 < /dev/null
  echo "$id $?" >&3
done
"""


def _cpio(entries: list[tuple[str, int, bytes]]) -> bytes:
    """A newc cpio archive of (name, mode, data) entries (directories have empty data)."""
    out = io.BytesIO()
    for ino, (name, mode, data) in enumerate([*entries, ("TRAILER!!!", 0, b"")], 1):
        raw = name.encode() + b"\0"
        header = "070701" + "".join(f"{v:08X}" for v in (ino, mode, 0, 0, 1, 0, len(data), 0, 0, 0, 0,
                                                          len(raw), 0))
        out.write(header.encode() + raw)
        out.write(b"\0" * (-(110 + len(raw)) % 4))
        out.write(data)
        out.write(b"\0" * (-len(data) % 4))
    return out.getvalue()


def load_order(kernel: Path, names: tuple[str, ...]) -> list[str]:
    """Module files to insmod, in order, for ``names`` and what they need (each once)."""
    orders = json.loads((kernel / "modules.json").read_text())
    return list(dict.fromkeys(f for name in names for f in orders[name]))


def build_initramfs(kernel: Path, path: Path) -> None:
    """The guest's initramfs: busybox, the boot modules in load order, and the init script."""
    d, x, f = stat.S_IFDIR | 0o755, stat.S_IFREG | 0o755, stat.S_IFREG | 0o644
    order = load_order(kernel, BOOT_MODULES)
    entries = [("bin", d, b""), ("modules", d, b""), ("init", x, INIT.encode()),
               ("bin/busybox", x, BUSYBOX.read_bytes()),
               ("modules.order", f, "".join(m + "\n" for m in order).encode())]
    entries += [(f"modules/{m}", f, (kernel / "modules" / m).read_bytes()) for m in order]
    path.write_bytes(_cpio(entries))


# ------------------------------------------------------------------------------------------------ the guest
class Guest:
    """One booted guest: ``sh(script)`` runs a shell script in it (the host's root file system, read-only, with
    /tmp, /run and the exchange folder ``/mnt`` = ``self.xchg`` writable); ``usbip_port()`` gives a fresh
    virtio-serial port bridged to a USB/IP server on the host. ``close()`` powers it off."""

    def __init__(self, workdir: Path, *, memory_mb: int = 1024, cpus: int = 2) -> None:
        self.workdir = Path(workdir)
        self.xchg = self.workdir / "xchg"
        (self.xchg / "cmd").mkdir(parents=True, exist_ok=True)
        kernel = cached_kernel()
        if kernel is None:
            raise GuestError(missing() or "no kernel")
        self.kernel = kernel
        self.kernel_version = (kernel / "version").read_text().strip()
        initrd = self.workdir / "initrd.cpio"
        build_initramfs(kernel, initrd)
        self.console_path = self.workdir / "console.log"
        self._sock = self.workdir / "s"
        self._sock.mkdir(exist_ok=True)
        cmd = ["qemu-system-x86_64", "-machine", "q35", "-accel", "tcg,thread=multi", "-cpu", "max",
               "-m", str(memory_mb), "-smp", str(cpus), "-nodefaults", "-display", "none", "-no-reboot",
               "-nic", "none", "-kernel", str(kernel / "vmlinuz"), "-initrd", str(initrd),
               "-append", "console=ttyS0 panic=-1 loglevel=6 usbcore.autosuspend=-1",
               "-serial", f"file:{self.console_path}",
               "-virtfs", "local,path=/,mount_tag=host,security_model=none,readonly=on,multidevs=remap",
               "-virtfs", f"local,path={self.xchg},mount_tag=xchg,security_model=none,multidevs=remap",
               "-qmp", f"unix:{self._sock / 'qmp'},server=on,wait=off",
               "-device", "virtio-serial-pci,max_ports=31",
               "-chardev", f"socket,id=agent,path={self._sock / 'agent'},server=on,wait=off",
               "-device", "virtserialport,chardev=agent,name=agent,id=agent"]
        for n in range(USBIP_PORTS):
            cmd += ["-chardev", f"socket,id=usbip{n},path={self._sock / f'usbip{n}'},server=on,wait=off",
                    "-device", f"virtserialport,chardev=usbip{n},name=usbip{n},id=usbip{n}"]
        self._qemu_log = open(self.workdir / "qemu.log", "wb")  # noqa: SIM115 (closed in close())
        self.proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=self._qemu_log, stderr=subprocess.STDOUT)
        self._ids = itertools.count(1)
        self._ports = iter(range(USBIP_PORTS))
        self._bridges: dict[str, UsbipBridge] = {}
        self._agent: socket.socket | None = None
        self._agent_buf = b""
        self._qmp: socket.socket | None = None
        self._qmp_thread: threading.Thread | None = None
        self._closed = False
        t0 = time.monotonic()
        try:
            self._agent = self._connect(self._sock / "agent")
            self._qmp = self._connect(self._sock / "qmp")
            self._qmp_start()
            self._wait_console("rollcam-guest: ready", BOOT_TIMEOUT_S)
        except BaseException:
            self.close()
            raise
        self.boot_s = time.monotonic() - t0

    # -------------------------------------------------------------------------------------------- plumbing
    def _connect(self, path: Path, timeout_s: float = 30.0) -> socket.socket:
        deadline = time.monotonic() + timeout_s
        while True:
            if self.proc.poll() is not None:
                raise GuestError(f"QEMU exited with {self.proc.returncode}: {self._tail(self.workdir / 'qemu.log')}")
            try:
                s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                s.connect(str(path))
                return s
            except OSError:
                s.close()
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)

    @staticmethod
    def _tail(path: Path, n: int = 2500) -> str:
        try:
            return path.read_bytes()[-n:].decode(errors="replace")
        except OSError:
            return ""

    def console(self) -> str:
        """Everything the guest's serial console printed (the kernel's log at loglevel 6 and the init's)."""
        return self._tail(self.console_path, 1 << 22)

    def oops(self) -> str | None:
        """The guest kernel's first oops, BUG or corruption report on the console (``find_oops``), or None."""
        return find_oops(self.console())

    def sound(self) -> bool:
        """Whether the guest runs and its kernel has reported no oops (``oops``)."""
        return not self._closed and self.proc.poll() is None and self.oops() is None

    def _wait_console(self, text: str, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while text not in self.console():
            if self.proc.poll() is not None:
                raise GuestError(f"the guest stopped during boot:\n{self._tail(self.console_path)}")
            if time.monotonic() > deadline:
                raise GuestError(f"no {text!r} within {timeout_s:.0f} s:\n{self._tail(self.console_path)}")
            time.sleep(0.1)

    def _qmp_start(self) -> None:
        qmp = self._qmp
        assert qmp is not None
        qmp.sendall(b'{"execute": "qmp_capabilities"}\n')
        self._qmp_thread = threading.Thread(target=self._qmp_events, name="guest-qmp", daemon=True)
        self._qmp_thread.start()

    def _qmp_events(self) -> None:
        """Read QMP events: a guest that closes a USB/IP port ends the bridged TCP connection (a detach)."""
        buf = b""
        while True:
            try:
                chunk = self._qmp.recv(65536) if self._qmp else b""
            except OSError:
                return
            if not chunk:
                return
            buf += chunk
            while b"\n" in buf:
                line, buf = buf.split(b"\n", 1)
                try:
                    msg = json.loads(line)
                except ValueError:
                    continue
                if msg.get("event") == "VSERPORT_CHANGE" and not msg["data"]["open"]:
                    bridge = self._bridges.get(msg["data"]["id"])
                    if bridge is not None:
                        bridge.guest_closed()

    # -------------------------------------------------------------------------------------------- commands
    def sh(self, script: str, timeout_s: float = 120.0, check: bool = True) -> tuple[int, str]:
        """Run ``script`` with /bin/sh in the guest (working folder /mnt); returns (exit status, output).
        ``check``: a non-zero status raises ``GuestError`` with the output."""
        cmd_id = next(self._ids)
        path = self.xchg / "cmd" / f"{cmd_id}.sh"
        path.write_text(script)
        assert self._agent is not None
        self._agent.sendall(f"{cmd_id}\n".encode())
        deadline = time.monotonic() + timeout_s
        while True:
            line, sep, rest = self._agent_buf.partition(b"\n")
            if sep:
                self._agent_buf = rest
                got_id, rc = line.decode().split()
                if int(got_id) == cmd_id:
                    break
                continue
            left = deadline - time.monotonic()
            if left <= 0 or self.proc.poll() is not None:
                raise GuestError(f"guest command {cmd_id} did not finish within {timeout_s:.0f} s:\n{script}\n"
                                 f"console:\n{self._tail(self.console_path)}")
            if select.select([self._agent], [], [], min(left, 1.0))[0]:
                chunk = self._agent.recv(4096)
                if not chunk:
                    raise GuestError(f"the guest agent went away:\n{self._tail(self.console_path)}")
                self._agent_buf += chunk
        out = (self.xchg / "cmd" / f"{cmd_id}.out").read_text(errors="replace")
        if check and int(rc) != 0:
            raise GuestError(f"guest command exited with {rc}:\n{script}\n--- output:\n{out}\n"
                             f"--- kernel log (last lines):\n{self._kernel_tail()}")
        return int(rc), out

    def load_module(self, name: str) -> None:
        """Load one of ``EXTRA_MODULES`` (and what it needs) into the guest."""
        mods = self.xchg / "modules"
        mods.mkdir(exist_ok=True)
        order = load_order(self.kernel, (name,))
        for m in order:
            shutil.copy2(self.kernel / "modules" / m, mods / m)
        self.sh("for m in " + " ".join(order) + "; do n=${m%.ko}; n=$(echo $n | tr - _); "
                "grep -q \"^$n \" /proc/modules || busybox insmod /mnt/modules/$m || exit 1; done")

    def video_node(self, card: str, index: int = 0, timeout_s: float = 30.0) -> str:
        """The /dev/videoN whose driver names it ``card`` (a prefix), interface ``index`` (uvcvideo: 0 is the
        capture node, 1 the metadata node), once it appears."""
        script = (f"for i in $(seq {int(timeout_s * 10)}); do for v in /sys/class/video4linux/video*; do "
                  f"case \"$(cat $v/name 2>/dev/null)\" in \"{card}\"*) "
                  f"[ \"$(cat $v/index)\" = {index} ] && echo /dev/${{v##*/}} && exit 0;; esac; done; sleep 0.1; "
                  "done; exit 1")
        return self.sh(script)[1].strip()

    def _kernel_tail(self, lines: int = 40) -> str:
        """The end of the guest kernel's log, for an error message (or why it could not be read)."""
        try:
            return "\n".join(self.sh("dmesg", timeout_s=30, check=False)[1].splitlines()[-lines:])
        except GuestError as e:
            return f"(not readable: {str(e).splitlines()[0]})"

    def dmesg(self) -> str:
        """The guest kernel's ring buffer."""
        return self.sh("dmesg")[1]

    @contextlib.contextmanager
    def usbip_port(self, server: tuple[str, int]) -> Iterator[int]:
        """A TCP port on the guest's loopback whose one connection reaches ``server`` (a rollcam USB/IP server
        on the host), for a guest ``usbip --tcp-port PORT ...`` command. The guest side is a socat that takes
        one connection and ends with it."""
        n = next(self._ports, None)
        if n is None:
            raise GuestError(f"all {USBIP_PORTS} USB/IP ports of this guest are used")
        name = f"usbip{n}"
        bridge = UsbipBridge(self._connect(self._sock / name), server)
        self._bridges[name] = bridge
        port = 3240 + n
        self.sh(f"setsid socat TCP-LISTEN:{port},bind=127.0.0.1,reuseaddr GOPEN:/dev/virtio-ports/{name} "
                f"</dev/null >/tmp/socat{n}.log 2>&1 &\n"
                f"for i in $(seq 100); do grep -q ':{port:04X} ' /proc/net/tcp && exit 0; sleep 0.1; done; exit 1")
        yield port

    def kill(self) -> None:
        """Kill QEMU: the guest vanishes mid-whatever, closing nothing (its bridged connections stay open, unread,
        as a peer that lost power leaves them)."""
        self.proc.kill()
        self.proc.wait()

    def close(self) -> None:
        """Power the guest off (QEMU is killed if it does not quit) and stop the bridges."""
        if self._closed:
            return
        self._closed = True
        with contextlib.suppress(OSError):
            if self._qmp is not None:
                self._qmp.sendall(b'{"execute": "quit"}\n')
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        for b in self._bridges.values():
            b.close()
        for s in (self._agent, self._qmp):
            if s is not None:
                s.close()
        self._qemu_log.close()


def find_oops(console: str) -> str | None:
    """The first oops, BUG or corruption report (``OOPS_MARKERS``) in a guest's console text, with the lines
    around it (its call trace), or None when the kernel reported none."""
    lines = console.splitlines()
    for i, line in enumerate(lines):
        if any(m in line for m in OOPS_MARKERS):
            return "\n".join(lines[max(0, i - 5):i + 40])
    return None


class GuestSlot:
    """The kernel tests' shared guest: ``get()`` hands out the running guest, or boots a fresh one where the last
    one broke (its kernel oopsed, or QEMU is gone), so one kernel bug costs the test that met it and not every
    test after it. ``workdir()`` gives each guest a folder of its own; ``boot`` boots one there."""

    def __init__(self, workdir: Callable[[], Path], boot: Callable[[Path], Guest] = Guest) -> None:
        self._workdir = workdir
        self._boot = boot
        self._guest: Guest | None = None
        self.boots = 0

    def get(self) -> Guest:
        """A sound guest: the current one, or a fresh one in place of a broken one."""
        if self._guest is not None and not self._guest.sound():
            self._guest.close()
            self._guest = None
        if self._guest is None:
            self._guest = self._boot(self._workdir())
            self.boots += 1
        return self._guest

    def close(self) -> None:
        """Power the current guest off."""
        if self._guest is not None:
            self._guest.close()
            self._guest = None


class UsbipBridge:
    """Relays one virtio-serial port of the guest to a TCP server on the host: the TCP connection opens when
    the guest first sends, and closes when the server closes it or the guest closes the port."""

    def __init__(self, port: socket.socket, server: tuple[str, int]) -> None:
        self.port, self.server = port, server
        self.tcp: socket.socket | None = None
        self._lock = threading.Lock()
        self._stop = False
        self.thread = threading.Thread(target=self._run, name="usbip-bridge", daemon=True)
        self.thread.start()

    def guest_closed(self) -> None:
        """The guest closed its end: the importer is gone."""
        with self._lock:
            if self.tcp is not None:
                with contextlib.suppress(OSError):
                    self.tcp.shutdown(socket.SHUT_RDWR)

    def _run(self) -> None:
        while not self._stop:
            socks = [self.port] + ([self.tcp] if self.tcp is not None else [])
            try:
                ready = select.select(socks, [], [], 0.5)[0]
            except (OSError, ValueError):
                return
            for s in ready:
                try:
                    data = s.recv(1 << 20)
                except OSError:
                    data = b""
                if s is self.port:
                    if not data:
                        return  # QEMU went away
                    with self._lock:
                        if self.tcp is None:
                            self.tcp = socket.create_connection(self.server)
                    try:
                        self.tcp.sendall(data)
                    except OSError:
                        self._drop_tcp()
                elif data:
                    self.port.sendall(data)
                else:
                    self._drop_tcp()

    def _drop_tcp(self) -> None:
        with self._lock:
            if self.tcp is not None:
                self.tcp.close()
                self.tcp = None

    def close(self) -> None:
        self._stop = True
        self.thread.join(timeout=2)
        self._drop_tcp()
        self.port.close()


if __name__ == "__main__":
    if sys.argv[1:] == ["prepare"]:
        print(prepare())
    else:
        sys.exit("usage: python tests/guest.py prepare   (fills the kernel cache the kernel tests boot)")
