"""The render study's cases (``rollcam bench render``): on one scene, every way of making a rolling-shutter frame
timed, its image and boxes kept, and the exact path checked against the brute-force reference.

``BenchConfig`` is what a run measures (``make_config``: the full and quick presets); ``SceneBench`` runs every
method on one scene and gives its table rows, errors against the baseline image and the exact RS boxes. The
runner, the frame-copy floor and the targets are in ``rollcam.benchmarks.bench``, which describes the methods.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.sim.compose import METHODS, compose_rs, composition_error
from rollcam.sim.footage import Footage
from rollcam.sim.render.renderer import Renderer
from rollcam.sim.render.result import LineTruth
from rollcam.sim.synthetic import SyntheticCamera

from .cameras import camera

SENSOR = "letsroll"
SCENES: dict[str, tuple[str, str]] = {
    "normal": ("normal", "none"),
    "fast": ("fast", "none"),
    "normal_ego": ("normal", "vehicle"),
    "fast_ego": ("fast", "vehicle"),
    "pan_ego": ("normal", "pan"),
    "walk_ego": ("normal", "walk"),
    "drone_ego": ("normal", "drone"),
}
"""Scene name -> (walker speed preset, camera ego-motion preset); every ego-motion preset has a scene."""

LINE_RATE = "line"
"""Footage rate meaning "one frame per line time" (32,400 fps on the study's camera)."""

_FIELDS = ("left", "right", "area", "visible")


@dataclass(frozen=True)
class BenchConfig:
    """What one bench run measures; ``make_config`` gives the full and quick presets."""

    width: int = 1920
    height: int = 1080
    n_pedestrians: int = 20
    seed: int = 0
    props: bool = False  # street props (parked cars, trees, poles, ...) in the scene
    scenes: tuple[str, ...] = tuple(SCENES)
    bands: tuple[int, ...] = (1, 2, 4, 8, 16, 64, 256)
    footage_fps: tuple[int | str, ...] = (240, 960, LINE_RATE)
    footage_scenes: tuple[str, ...] | None = None  # None: every scene
    compose_methods: tuple[str, ...] = METHODS
    n_frames: int = 5  # timed frames of exact and gs
    n_frames_other: int = 3  # timed frames of each banded K
    compose_repeats: int = 3
    full_reference: bool = True  # False: time the reference on sampled lines, baseline = exact
    reference_stride: int = 27
    reference_stride_ego: int = 108
    check_size: tuple[int, int] = (192, 108)  # full-image exact == reference check when not full_reference
    flow_preset: str = "fast"
    flow_margin_px: int = 48
    first_frame: int = 10
    frame_step: int = 7
    memcpy_repeats: int = 200
    scaling_sizes: tuple[tuple[int, int], ...] = ((640, 360), (1280, 720), (1920, 1080), (3840, 2160))
    scaling_walkers: tuple[int, ...] = (0, 20, 200)
    scaling_frames: int = 3
    quick: bool = False

    def __post_init__(self) -> None:
        bad = [s for s in self.scenes if s not in SCENES]
        if bad or not self.scenes:
            raise ConfigError(f"bench scenes {bad or self.scenes!r} are not a subset of {list(SCENES)}")
        if self.width <= 0 or self.height <= 0:
            raise ConfigError(f"bench size must be positive, got {self.width}x{self.height}")
        if any(m not in METHODS for m in self.compose_methods):
            raise ConfigError(f"compose methods {self.compose_methods!r} must be among {METHODS}")
        if any(k < 1 for k in self.bands) or min(self.n_frames, self.n_frames_other, self.compose_repeats) < 1:
            raise ConfigError("bands, n_frames, n_frames_other and compose_repeats must be >= 1")


def make_config(quick: bool = False, width: int = 1920, height: int = 1080, **overrides: Any) -> BenchConfig:
    """The full (several minutes) or quick (under a minute) preset, with any field overridden."""
    base = BenchConfig(width=width, height=height)
    if quick:
        base = dataclasses.replace(
            base, quick=True, scenes=("normal", "normal_ego", "pan_ego", "walk_ego", "drone_ego"),
            bands=(1, 4, 16, 64), footage_fps=(240, 960),
            footage_scenes=("normal",), n_frames=5, n_frames_other=1, compose_repeats=3, full_reference=False,
            memcpy_repeats=100, scaling_sizes=((640, 360), (1920, 1080), (3840, 2160)), scaling_frames=2,
        )
    try:
        return dataclasses.replace(base, **overrides)
    except TypeError as exc:
        raise ConfigError(f"unknown bench option: {exc}") from None


# ---------------------------------------------------------------------------------------------- pieces
def banded_times_ns(times_ns: np.ndarray, k: int) -> np.ndarray:
    """Line times quantised into ``k`` near-equal bands of lines, each band at its middle instant.

    A band's instant is halfway between its first and last lines' times (its middle line's time when it
    has an odd number of lines). ``k=1`` is one GS frame at mid-readout; ``k >= lines`` the exact times.
    """
    t = np.asarray(times_ns, dtype=np.int64)
    k = min(int(k), t.size)
    edges = (np.arange(k + 1) * t.size) // k
    first, last = t[edges[:-1]], t[edges[1:] - 1]
    return np.repeat(first + (last - first) // 2, np.diff(edges))


def box_error_px(boxes: Sequence[Any], truth: Sequence[Any]) -> tuple[float | None, int]:
    """(worst coordinate difference over actors boxed in both, actors boxed in only one of them)."""
    worst: float | None = None
    mismatched = 0
    for a, b in zip(boxes, truth, strict=True):
        if a is None and b is None:
            continue
        if a is None or b is None:
            mismatched += 1
            continue
        d = max(abs(float(x) - float(y)) for x, y in zip(a, b, strict=True))
        worst = d if worst is None else max(worst, d)
    return worst, mismatched


def _gather_truth(truths: Sequence[LineTruth], k_per_line: np.ndarray) -> LineTruth:
    """The truth of a composed frame whose line i comes from footage frame ``k_per_line[i]``."""
    out = LineTruth.empty(truths[0].left.shape[0], k_per_line.size, truths[0].transposed)
    for i, k in enumerate(k_per_line.tolist()):
        for name in _FIELDS:
            getattr(out, name)[:, i] = getattr(truths[k], name)[:, i]
    return out


def _camera(cfg: BenchConfig, scene: str, size: tuple[int, int] | None = None) -> SyntheticCamera:
    speed, ego = SCENES[scene]
    w, h = size or (cfg.width, cfg.height)
    return camera(SENSOR, {"scene": "street", "seed": cfg.seed, "speed": speed, "pedestrians": cfg.n_pedestrians,
                           "ego": ego, "props": cfg.props}, size=(w, h))


def _footage_fps(cam: SyntheticCamera, spec: int | str) -> Fraction:
    if spec == LINE_RATE:
        t = cam.settings.timing
        return Fraction(t.pixel_rate_hz, t.line_length_pck)
    return Fraction(spec)


def _ratio(a: float | None, b: float | None) -> float | None:
    """a / b rounded, or None when either is missing (or b is zero: a copy below the clock's resolution)."""
    return None if a is None or not b else round(a / b, 2)


def _median_ms(samples_s: list[float]) -> float:
    return 1e3 * float(np.median(samples_s))


# ------------------------------------------------------------------------------------------ one scene
class SceneBench:
    """Every method on one scene: timings, the images and boxes at the scored instant."""

    def __init__(self, cfg: BenchConfig, scene: str, say: Callable[[str], None]) -> None:
        self.cfg, self.scene, self.say = cfg, scene, say
        self.cam = _camera(cfg, scene)
        self.renderer: Renderer = self.cam.renderer
        self.by_column = self.cam.settings.readout.by_column
        self.frames = [cfg.first_frame + i * cfg.frame_step for i in range(max(cfg.n_frames, cfg.n_frames_other))]
        self.rs_times = self.cam.line_times_ns(cfg.first_frame, "rolling")
        self.results: dict[str, dict[str, Any]] = {}
        self.skipped: list[dict[str, str]] = []
        self.checks: dict[str, Any] = {}

    def _render(self, times: np.ndarray):
        return self.renderer.render_lines(times, by_column=self.by_column)

    def _timed_render(self, name: str, times_of: Callable[[int], np.ndarray], n: int, **extra: Any) -> None:
        samples, cpu, kept = [], [], None
        for i in self.frames[:n]:
            times = times_of(i)
            c0, t0 = time.process_time(), time.perf_counter()
            res = self._render(times)
            samples.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
            if i == self.cfg.first_frame:
                kept = res
        assert kept is not None
        self.results[name] = {"ms": _median_ms(samples), "cpu_ms": _median_ms(cpu), "n_timed": len(samples),
                              "image": kept.image, "boxes": kept.truth.boxes(), **extra}

    def run(self) -> None:
        cfg, cam = self.cfg, self.cam
        self.say(f"{self.scene}: warm-up")
        self._render(cam.line_times_ns(0, "global"))  # builds the static layer (and compiles on a cold cache)
        self._render(cam.line_times_ns(0, "rolling"))
        self.say(f"{self.scene}: exact, gs ({cfg.n_frames} frames each)")
        self._timed_render("exact", lambda i: cam.line_times_ns(i, "rolling"), cfg.n_frames, kind="render")
        self._timed_render("gs", lambda i: cam.line_times_ns(i, "global"), cfg.n_frames, kind="render",
                           note="one GS frame at the first line's time; its error is the RS effect")
        for k in cfg.bands:
            self.say(f"{self.scene}: banded_{k}")
            self._timed_render(f"banded_{k}", lambda i, k=k: banded_times_ns(cam.line_times_ns(i, "rolling"), k),
                               cfg.n_frames_other, kind="render")
        ref_frames = self._reference()
        for spec in cfg.footage_fps:
            label = f"footage_{float(_footage_fps(cam, spec)):g}_*"
            if cfg.footage_scenes is not None and self.scene not in cfg.footage_scenes:
                self.skipped.append({"scene": self.scene, "method": label,
                                     "why": f"footage is composed on scenes {list(cfg.footage_scenes)} only"})
            elif spec == LINE_RATE and ref_frames is None:
                self.skipped.append({"scene": self.scene, "method": label,
                                     "why": "line-rate footage costs a full reference (one render per line); "
                                            "only with the full reference"})
            else:
                self._footage(spec, ref_frames if spec == LINE_RATE else None)

    def _reference(self) -> list[np.ndarray] | None:
        """Time the brute-force reference; with ``full_reference`` keep its image, truth and renders."""
        cfg, h = self.cfg, self.rs_times.size
        ego = self.renderer.camera_moving
        stride = 1 if cfg.full_reference else (cfg.reference_stride_ego if ego else cfg.reference_stride)
        lines = np.arange(0, h, stride)
        keep_frames = cfg.full_reference and LINE_RATE in cfg.footage_fps and (
            cfg.footage_scenes is None or self.scene in cfg.footage_scenes)
        self.say(f"{self.scene}: reference, {lines.size} full renders" + (" (slow)" if lines.size > 100 else ""))
        image = np.empty_like(self.results["exact"]["image"])
        truth = LineTruth.empty(self.renderer.n_actors, h, self.by_column)
        frames: list[np.ndarray] = []
        elapsed = 0.0
        for n, r in enumerate(lines.tolist()):
            t0 = time.perf_counter()
            full = self.renderer.reference_frame(int(self.rs_times[r]), by_column=self.by_column)
            if self.by_column:
                image[:, r] = full.image[:, r]
            else:
                image[r] = full.image[r]
            for name in _FIELDS:
                getattr(truth, name)[:, r] = getattr(full.truth, name)[:, r]
            elapsed += time.perf_counter() - t0
            if keep_frames:
                frames.append(full.image)
            if n % 270 == 269:
                self.say(f"{self.scene}: reference {n + 1}/{lines.size} lines")
        res: dict[str, Any] = {"ms": 1e3 * elapsed * h / lines.size, "n_timed": 1, "kind": "reference"}
        if cfg.full_reference:
            res.update(image=image, boxes=truth.boxes())
        else:
            exact = self.results["exact"]["image"]
            sel = (slice(None), lines) if self.by_column else lines
            err = composition_error(image[sel], exact[sel])
            res.update(image=None, boxes=None, err=err, note=(
                f"timed on {lines.size} of {h} lines' full renders (every {stride}th), scaled to {h}; "
                f"error on those lines vs exact"))
            self.checks["sampled_lines_max_abs_diff_dn"] = err["max_abs_err_dn"]
        self.results["reference"] = res
        return frames if keep_frames else None

    def _footage(self, spec: int | str, ref_frames: list[np.ndarray] | None) -> None:
        cfg, times = self.cfg, self.rs_times
        fps = _footage_fps(self.cam, spec)
        t_first = int(times.min())
        rel = times - t_first
        label = f"footage_{round(fps) if fps.denominator == 1 else float(fps):g}"
        order = np.argsort(rel, kind="stable")
        if ref_frames is not None:
            # The reference's renders, line by line in readout order: frame k is the k-th line read, at its
            # exact line time (the footage's rounded timestamp is within 1 ns of it; compose snaps 1 ns).
            frames = [ref_frames[r] for r in order.tolist()]
            truths = None
            input_ms = self.results["reference"]["ms"]
        else:
            probe = Footage.from_frames([np.zeros((1, 1), np.uint8)], fps)  # the footage clock, before frames
            n = 1
            while probe.time_ns(n - 1) < int(rel.max()):
                n += 1
            self.say(f"{self.scene}: {label}: rendering {n} GS footage frames")
            frames, truths = [], []
            t0 = time.perf_counter()
            for k in range(n):
                res = self._render(np.full(times.size, t_first + probe.time_ns(k)))
                frames.append(res.image)
                truths.append(res.truth)
            input_ms = 1e3 * (time.perf_counter() - t0)
        footage = Footage.from_frames(frames, fps)
        a = footage.index_at_or_before_ns(rel)
        b = np.minimum(a + 1, len(footage) - 1)
        nearest = np.where(rel - footage.times_ns(a) <= footage.times_ns(b) - rel, a, b)
        for method in cfg.compose_methods:
            kw: dict[str, Any] = {"by_column": self.by_column}
            note = f"{len(footage)} footage frames at {float(fps):g} fps; composition only"
            if method == "flow":
                kw.update(flow_preset=cfg.flow_preset, flow_margin_px=cfg.flow_margin_px)
                note += f"; flow_preset={cfg.flow_preset!r}, flow_margin_px={cfg.flow_margin_px}"
            self.say(f"{self.scene}: {label}_{method}")
            image = compose_rs(footage, 0, rel, method, **kw)  # warm-up, and the scored image
            samples = []
            for _ in range(cfg.compose_repeats):
                t0 = time.perf_counter()
                compose_rs(footage, 0, rel, method, **kw)
                samples.append(time.perf_counter() - t0)
            boxes = None
            if truths is None and np.array_equal(nearest[order], np.arange(rel.size)):
                boxes = self.results["reference"]["boxes"]  # every line is its own footage frame's line
            elif method == "nearest" and truths is not None:
                boxes = _gather_truth(truths, nearest).boxes()
            else:
                note += "; blended lines have no ground truth, so no boxes"
            self.results[f"{label}_{method}"] = {
                "ms": _median_ms(samples), "n_timed": len(samples), "image": image, "boxes": boxes,
                "kind": "compose", "input_ms": input_ms, "note": note + f" (median of {len(samples)} repeats)"}

    def full_image_check(self) -> float:
        """Max |exact - reference| (DN) on the whole frame of this scene at ``check_size``."""
        cam = _camera(self.cfg, self.scene, self.cfg.check_size)
        times = cam.line_times_ns(self.cfg.first_frame, "rolling")
        bc = cam.settings.readout.by_column
        exact = cam.renderer.render_lines(times, by_column=bc).image
        ref = cam.renderer.reference_lines(times, by_column=bc).image
        return composition_error(exact, ref)["max_abs_err_dn"]

    def rows(self, floor: dict[str, float]) -> list[dict[str, Any]]:
        """The table rows of this scene, errors against the baseline image and the exact RS boxes; costs also
        in ``floor``'s frame copies (``bench.memcpy_floor``), wall against wall and CPU against CPU."""
        floor_ms, cold_ms = floor["ms"], floor["cold_ms"]
        ref = self.results["reference"]
        baseline = ref["image"] if ref["image"] is not None else self.results["exact"]["image"]
        truth_boxes = self.results["exact"]["boxes"]
        out = []
        for name, r in self.results.items():
            if r["image"] is not None:
                err = composition_error(r["image"], baseline)
            else:
                err = r["err"]
            box_err, mismatched = (None, 0) if r["boxes"] is None else box_error_px(r["boxes"], truth_boxes)
            out.append({
                "scene": self.scene, "method": name, "kind": r["kind"],
                "ms_per_frame": round(r["ms"], 4),
                "cpu_ms_per_frame": None if r.get("cpu_ms") is None else round(r["cpu_ms"], 4),
                "x_memcpy": round(r["ms"] / floor_ms, 2),
                "x_memcpy_cold": round(r["ms"] / cold_ms, 2),
                "x_memcpy_cpu": _ratio(r.get("cpu_ms"), floor.get("cpu_ms")),
                "x_memcpy_cold_cpu": _ratio(r.get("cpu_ms"), floor.get("cold_cpu_ms")),
                "speedup_vs_reference": round(ref["ms"] / r["ms"], 2),
                "mean_abs_err_dn": round(err["mean_abs_err_dn"], 5),
                "max_abs_err_dn": err["max_abs_err_dn"],
                "max_box_err_px": None if box_err is None else round(box_err, 3),
                "boxes_mismatched": mismatched,
                "n_timed": r["n_timed"],
                "input_ms": None if r.get("input_ms") is None else round(r["input_ms"], 2),
                "note": r.get("note", ""),
            })
        return out
