"""Multi-camera rigs: N cameras of one scene (stereo, surround) on one world clock, synchronised or not.

A rig is declared in one line of text (``RigSpec.parse``), the same in ``rollcam emulate --rig`` and the ``emu:``
URI's ``rig=`` option::

    stereo,baseline=0.12,sync=hw,offset_ns=0/1500,ppm=0/20,jitter_ns=0/200,seed=7
    surround,n=6,radius=0.1,sync=free

Every camera is the same ``CameraSpec`` (one scene, one seed) moved to its place in the rig (``mount_m``,
``mount_yaw_deg``): stereo puts camera 1 ``baseline`` m to the right of camera 0; surround turns camera ``i``
``i * 360 / n`` degrees, ``radius`` m out from the rig's centre. Each camera has its own clock
(``CameraClock``): ``device_ns = floor((world_ns + offset_ns) * (1 + ppm * 1e-6))``, integer ns, and the
timestamp it stamps on a frame carries a seeded jitter, uniform in ``[-jitter_ns, jitter_ns]``.

``sync=hw`` is one trigger line: frame ``k`` of every camera starts exposing at the same world instant (camera 0's
nominal frame ``k`` on the world clock), each camera then reading its rows with its own sensor's line timing on
its own clock. ``sync=free``: each camera runs its own frame timing on its own clock from the rig's start, so a
drifting camera's frames walk away from the others'. The scene is rendered at world time; the frame says what the
host sees (timestamp and row times on the camera's device clock) and its truth says when in the world that was
(``meta["rig"]``: ``world_start_ns``, the exact device start before jitter, and the jitter).

``Rig`` reads a rig's frames without pacing (the ``emu:`` source's ``rig=``); ``LiveRig`` runs one in real time,
each camera a ``FirmwareCamera`` on its own device clock (``rollcam emulate --rig``, ``rollcam run`` devices).
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError, DeviceError
from rollcam.common.lifecycle import Closeable, Worker
from rollcam.common.values import finite_float, non_negative_int, positive_float, positive_int
from rollcam.sim.frame import Frame
from rollcam.sim.timing import NS_PER_S

from .camera import FirmwareCamera
from .spec import CameraSpec
from .stream import Clock, FramePlan, schedule_of

KINDS = ("stereo", "surround")
SYNCS = ("hw", "free")
MAX_CAMERAS = 16
MAX_OFFSET_NS = 10**15  # about 11.6 days either way
MAX_PPM = 1000.0
MAX_JITTER_NS = 10**9


@dataclass(frozen=True)
class CameraClock:
    """One camera's clock against the world clock: offset (ns), drift (ppm) and the timestamp jitter (ns) it
    stamps frames with, seeded per camera and frame."""

    offset_ns: int = 0
    ppm: float = 0.0
    jitter_ns: int = 0
    seed: int = 0
    index: int = 0

    @property
    def rate(self) -> Fraction:
        """Device ns per world ns, exactly (the ppm as written, e.g. 20.5 -> 1.0000205)."""
        return 1 + Fraction(str(self.ppm)) / 1_000_000

    def device_ns(self, world_ns: int) -> int:
        """The device clock's reading at world time ``world_ns``."""
        return int((int(world_ns) + self.offset_ns) * self.rate // 1)

    def world_ns(self, device_ns: int) -> int:
        """The first world ns at which the device clock reads ``device_ns`` or more (``device_ns``'s inverse)."""
        w = int(-(-Fraction(int(device_ns)) // self.rate)) - self.offset_ns  # ceil(device / rate) - offset
        while self.device_ns(w - 1) >= device_ns:
            w -= 1
        while self.device_ns(w) < device_ns:
            w += 1
        return w

    def jitter(self, seq: int) -> int:
        """The jitter on frame ``seq``'s timestamp: uniform integer ns in ``[-jitter_ns, jitter_ns]``, the same
        for the same seed, camera and frame."""
        if self.jitter_ns == 0:
            return 0
        rng = np.random.default_rng([self.seed, self.index, int(seq)])
        return int(rng.integers(-self.jitter_ns, self.jitter_ns + 1))


@dataclass(frozen=True)
class RigSpec:
    """A rig declaration: its kind, cameras, geometry, trigger and clocks (parse it from text with ``parse``)."""

    kind: str = "stereo"
    n: int = 2
    baseline_m: float = 0.12
    radius_m: float = 0.0
    sync: str = "hw"
    clocks: tuple[CameraClock, ...] = (CameraClock(), CameraClock(index=1))

    @classmethod
    def parse(cls, text: str, owner: str = "rig") -> RigSpec:
        """``KIND[,key=value...]``: kind ``stereo`` or ``surround``; keys ``n`` (surround's cameras, default 4),
        ``baseline`` (stereo, m, default 0.12), ``radius`` (surround, m, default 0), ``sync`` (hw | free,
        default hw), ``offset_ns``, ``ppm``, ``jitter_ns`` (one value for every camera or one per camera joined
        by ``/``) and ``seed`` (the jitter's). Bad text raises ConfigError naming ``owner`` and the part."""
        parts = [p.strip() for p in str(text).split(",")]
        kind = parts[0].lower()
        if kind not in KINDS:
            raise ConfigError(f"{owner}: rig kind {parts[0]!r} is not one of {KINDS} (e.g. stereo,baseline=0.12)")
        keys: dict[str, str] = {}
        for part in parts[1:]:
            key, eq, value = part.partition("=")
            if not eq or not key.strip():
                raise ConfigError(f"{owner}: rig part {part!r} is not key=value")
            keys[key.strip().lower()] = value.strip()
        allowed = {"n", "sync", "offset_ns", "ppm", "jitter_ns", "seed",
                   *(("baseline",) if kind == "stereo" else ("radius",))}
        unknown = sorted(set(keys) - allowed)
        if unknown:
            raise ConfigError(f"{owner}: rig key {unknown[0]!r} is not one of {sorted(allowed)} for a {kind} rig")

        def value(key: str, parse: Any, default: Any) -> Any:
            if key not in keys:
                return default
            try:
                return parse(keys[key])
            except (TypeError, ValueError) as exc:
                raise ConfigError(f"{owner}: rig {key}={keys[key]!r} is invalid ({exc})") from None

        n = value("n", positive_int, 2 if kind == "stereo" else 4)
        if kind == "stereo" and n != 2:
            raise ConfigError(f"{owner}: a stereo rig has 2 cameras, not n={n}")
        if not 1 <= n <= MAX_CAMERAS:
            raise ConfigError(f"{owner}: rig n={n} is not in 1..{MAX_CAMERAS}")
        sync = value("sync", str.lower, "hw")
        if sync not in SYNCS:
            raise ConfigError(f"{owner}: rig sync={sync!r} is not one of {SYNCS}")

        def per_camera(key: str, parse: Any, limit: float) -> list[Any]:
            raw = keys.get(key, "0").split("/")
            if len(raw) not in (1, n):
                raise ConfigError(f"{owner}: rig {key}={keys[key]!r} gives {len(raw)} values for {n} cameras "
                                  "(give one, or one per camera joined by '/')")
            try:
                got = [parse(r) for r in raw]
            except (TypeError, ValueError) as exc:
                raise ConfigError(f"{owner}: rig {key}={keys[key]!r} is invalid ({exc})") from None
            bad = [g for g in got if abs(g) > limit]
            if bad:
                raise ConfigError(f"{owner}: rig {key}={bad[0]!r} is beyond +-{limit:g}")
            return got * n if len(got) == 1 else got

        seed = value("seed", non_negative_int, 0)
        offsets = per_camera("offset_ns", int, MAX_OFFSET_NS)
        ppms = per_camera("ppm", finite_float, MAX_PPM)
        jitters = per_camera("jitter_ns", non_negative_int, MAX_JITTER_NS)
        clocks = tuple(CameraClock(o, p, j, seed, i) for i, (o, p, j) in enumerate(zip(offsets, ppms, jitters,
                                                                                     strict=True)))
        return cls(kind, n, value("baseline", positive_float, 0.12), value("radius", _non_negative, 0.0), sync,
                   clocks)

    def to_json(self) -> dict[str, Any]:
        """The declaration as plain JSON: kind, cameras, geometry, sync and each camera's clock."""
        geometry = {"baseline_m": self.baseline_m} if self.kind == "stereo" else {"radius_m": self.radius_m}
        return {"kind": self.kind, "n": self.n, **geometry, "sync": self.sync,
                "clocks": [{"offset_ns": c.offset_ns, "ppm": c.ppm, "jitter_ns": c.jitter_ns} for c in self.clocks],
                "seed": self.clocks[0].seed if self.clocks else 0}

    def to_text(self) -> str:
        """The declaration as ``parse`` reads it back."""
        geometry = f"baseline={self.baseline_m!r}" if self.kind == "stereo" else f"n={self.n},radius={self.radius_m!r}"
        per = {k: "/".join(str(getattr(c, k)) for c in self.clocks) for k in ("offset_ns", "ppm", "jitter_ns")}
        return (f"{self.kind},{geometry},sync={self.sync}," + ",".join(f"{k}={v}" for k, v in per.items())
                + f",seed={self.clocks[0].seed}")

    def mount(self, index: int) -> tuple[tuple[float, float, float], float]:
        """Camera ``index``'s place in the rig: (right, forward, up) m from camera 0's, and its yaw in degrees."""
        if self.kind == "stereo":
            return (self.baseline_m * index, 0.0, 0.0), 0.0
        yaw = 360.0 * index / self.n
        a = np.radians(yaw)
        # Around the rig's centre, radius m behind camera 0's place when index is 0 (so camera 0 stays put).
        return (float(self.radius_m * np.sin(a)), float(self.radius_m * (np.cos(a) - 1.0)), 0.0), yaw

    def camera_options(self, index: int) -> dict[str, str]:
        """The camera options that place camera ``index`` (``mount_m``, ``mount_yaw_deg``), as text."""
        (dx, dy, dz), yaw = self.mount(index)
        return {"mount_m": f"{dx!r},{dy!r},{dz!r}", "mount_yaw_deg": repr(yaw)}


def _non_negative(text: str) -> float:
    v = finite_float(text)
    if v < 0:
        raise ValueError("expected a number >= 0")
    return v


class Rig:
    """The cameras of one rig declaration, each a ``FirmwareCamera`` of the same spec moved to its place, and
    their frames on one world clock (``frame(i, k)``: camera ``i``'s frame ``k``), read without pacing from world
    time ``epoch_ns``."""

    def __init__(self, rig: RigSpec, spec: CameraSpec, epoch_ns: int = 0) -> None:
        self.rig = rig
        self.epoch_ns = int(epoch_ns)
        self.cameras = [FirmwareCamera(placed(rig, spec, i), clock=lambda: 0) for i in range(rig.n)]
        check_trigger(rig, spec)

    def world_start_ns(self, index: int, seq: int) -> int:
        """World time camera ``index``'s frame ``seq`` starts exposing its first line."""
        if self.rig.sync == "hw":  # the trigger: camera 0's nominal frame timing on the world clock
            return self.cameras[0].spec.settings.timing.frame_start_ns(seq, self.epoch_ns)
        return self.rig.clocks[index].world_ns(self.device_start_ns(index, seq))

    def device_start_ns(self, index: int, seq: int) -> int:
        """Camera ``index``'s own clock reading at that start (before the timestamp's jitter)."""
        clock = self.rig.clocks[index]
        if self.rig.sync == "hw":
            return clock.device_ns(self.world_start_ns(index, seq))
        timing = self.cameras[index].spec.settings.timing
        return timing.frame_start_ns(seq, clock.device_ns(self.epoch_ns))

    def frame(self, index: int, seq: int, shutter: str | None = None) -> Frame:
        """Camera ``index``'s frame ``seq``: rendered at its world times, stamped on its own clock."""
        camera = self.cameras[index]
        world = self.world_start_ns(index, seq)
        frame = camera.render(FramePlan(seq, schedule_of(camera.spec, world, seq)), shutter)
        return stamp(frame, self.rig.clocks[index], world, self.device_start_ns(index, seq), self.rig)


@dataclass(frozen=True)
class RigTimebase:
    """Camera ``clock.index`` of ``rig`` as a ``FirmwareCamera`` holds it (``timebase=``): its frames, planned on
    its own device clock, are rendered at world time and stamped back (``stamp``)."""

    rig: RigSpec
    clock: CameraClock

    def world_ns(self, device_ns: int) -> int:
        """World time of a device time of this camera."""
        return self.clock.world_ns(device_ns)

    def stamp(self, frame: Frame, world_start_ns: int, device_start_ns: int) -> Frame:
        """``frame`` (rendered from ``world_start_ns``) as this camera reports it."""
        return stamp(frame, self.clock, world_start_ns, device_start_ns, self.rig)


class LiveRig(Closeable):
    """A rig in real time, for ``rollcam emulate --rig``: one ``FirmwareCamera`` per camera on its own device
    clock (the world clock ``world`` through its ``CameraClock``, counted from the rig's start), streaming.
    ``sync=hw`` runs the trigger line: a thread that at camera 0's nominal frame starts on the world clock
    triggers every camera (trigger mode external) at that instant on its own clock."""

    def __init__(self, rig: RigSpec, spec: CameraSpec, world: Clock = time.monotonic_ns) -> None:
        check_trigger(rig, spec)
        self.rig = rig
        self.world = world
        # World time starts where no camera's clock reads below 0 (a device clock starts at 0 and counts up).
        self.world0 = world() - max(0, -min(c.offset_ns for c in rig.clocks))
        self.cameras = [FirmwareCamera(placed(rig, spec, i), clock=self._device_clock(c), boot_ns=0,
                                       timebase=RigTimebase(rig, c)) for i, c in enumerate(rig.clocks)]
        self.triggers = 0
        self._trigger: Worker | None = None
        if rig.sync == "hw":  # before any transport streams them: no frame starts but on the trigger line
            for cam in self.cameras:
                cam.set_trigger_mode("external")

    def _device_clock(self, clock: CameraClock) -> Clock:
        return lambda: clock.device_ns(self.world() - self.world0)

    def world_ns(self) -> int:
        """World time since the rig started (plus the largest negative offset, so every device clock is >= 0)."""
        return self.world() - self.world0

    def start(self) -> None:
        """Stream every camera (and, under hardware sync, start the trigger line)."""
        for cam in self.cameras:
            cam.stream_on()
        self.start_trigger()

    def start_trigger(self) -> None:
        """Under hardware sync, start the trigger line (idempotent): it triggers the cameras that stream, so
        a camera a program streams later (``rollcam run``) joins it at the next slot."""
        if self.rig.sync == "hw" and self._trigger is None:
            self._trigger = Worker(self._run_trigger, name="rollcam-rig-trigger", wrap=DeviceError)
            self._trigger.start()

    def check(self) -> None:
        """Re-raise what stopped the trigger line, if anything did."""
        if self._trigger is not None:
            self._trigger.check()

    def _run_trigger(self) -> None:
        assert self._trigger is not None
        timing = self.cameras[0].spec.settings.timing
        stop = self._trigger.stop_event
        k = 0
        while True:
            lead = self.world_ns()
            if timing.frame_start_ns(k) < lead - timing.frame_period_ns:
                # The line was held up (a busy machine, or the servers' start): go on from the next slot
                # rather than fire a burst, as a trigger generator that never fell behind would.
                k = lead * timing.pixel_rate_hz // (timing.frame_period_pck * NS_PER_S)
                while timing.frame_start_ns(k) < lead:
                    k += 1
            at = timing.frame_start_ns(k)
            if at > lead and stop.wait((at - lead) / 1e9):
                return
            if stop.is_set():
                return
            for cam, clock in zip(self.cameras, self.rig.clocks, strict=True):
                if cam.streaming:
                    with contextlib.suppress(DeviceError):  # stopped meanwhile: that camera misses this slot
                        cam.trigger(clock.device_ns(at))
            self.triggers += 1
            k += 1

    def _close(self) -> None:
        if self._trigger is not None:
            self._trigger.close()
        for cam in self.cameras:
            cam.stream_off()


def check_trigger(rig: RigSpec, spec: CameraSpec) -> None:
    """Under ``sync=hw`` a camera takes a trigger only once the frame before is read out (``DeviceStream.trigger``,
    as a sensor in external-trigger mode does), so exposure plus readout must fit the trigger period: ConfigError
    naming both when they do not."""
    if rig.sync != "hw":
        return
    sched = schedule_of(spec, 0)
    busy, period = sched.frame_due_ns(0), spec.settings.timing.frame_period_ns
    if busy > period:
        raise ConfigError(f"rig sync=hw: exposure + readout ({busy} ns) is longer than the trigger period "
                          f"({period} ns); shorten exposure_us or lower fps")


def placed(rig: RigSpec, spec: CameraSpec, index: int) -> CameraSpec:
    """``spec`` moved to camera ``index``'s place in ``rig``."""
    offset, yaw = rig.mount(index)
    return dataclasses.replace(spec, mount_m=offset, mount_yaw_deg=yaw)


def stamp(frame: Frame, clock: CameraClock, world_start_ns: int, device_start_ns: int, rig: RigSpec) -> Frame:
    """A frame rendered at world times, as its camera reports it: timestamp and row times on the camera's clock
    (jitter included), and the truth in ``meta["rig"]``. Row ``r`` was seen at world time ``world_start_ns +
    row_times_ns[r] - timestamp_ns`` (the drift within one frame, under ppm x frame time, is not rendered)."""
    jitter = clock.jitter(frame.sequence)
    shift = device_start_ns + jitter - int(frame.timestamp_ns)
    rows = None if frame.row_times_ns is None else frame.row_times_ns + np.int64(shift)
    truth = {"kind": rig.kind, "camera": clock.index, "cameras": rig.n, "sync": rig.sync,
             "world_start_ns": int(world_start_ns), "device_start_ns": int(device_start_ns), "jitter_ns": jitter,
             "offset_ns": clock.offset_ns, "ppm": clock.ppm}
    return dataclasses.replace(frame, timestamp_ns=device_start_ns + jitter, row_times_ns=rows,
                               meta={**frame.meta, "rig": truth})


def world_row_times_ns(frame: Frame) -> np.ndarray:
    """The world time each row of a rig camera's frame was seen at (its truth), int64 ns."""
    truth = frame.meta.get("rig")
    if truth is None or frame.row_times_ns is None:
        raise ConfigError("frame has no rig truth (not from a rig camera)")
    return frame.row_times_ns - np.int64(frame.timestamp_ns) + np.int64(truth["world_start_ns"])
