"""Per-line exposure windows and motion blur by adaptive time sampling.

Each line integrates the scene over its own window (rolling shutter: the window ends ``exposure`` after
it starts, one line time after the previous line's; global shutter: one window for all). The integral is
approximated by the midpoint rule with ``n`` samples per line, the fewest that keep every image point's
displacement between consecutive samples under ``bound_px`` (the rule event-camera simulators use:
step = bound / max image speed). A line no moving thing touches during its window gets one sample.

Image speed is measured, not guessed: each actor's render-space parts (capsule end points and radii, bar
edges) are evaluated at steps across the frame and the fastest displacement rate of any of them is its
speed; the lines it can touch during a window come from the renderer's conservative swept bounds. A moving
camera moves every line: its image speed is the rotation rate times the focal length (corner-corrected)
plus the translation speed over the camera's height (the nearest static surface assumed at that depth).

``integrate`` costs what the plan asks and no more: every (line, sample) pair is rendered in a few batched
calls (``Renderer.accumulate_samples``), and only where an actor is, as differences from the static
composite; lines nothing moves over stay the composite (shared, not copied), so a frame of fast walkers
with up to 192 samples per line costs its painted line samples, not 192 frame renders and copies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from itertools import pairwise

import numpy as np
from numba import njit, prange
from rollcam.common.errors import ConfigError

from ._jitcache import guard
from .render.egoblur import blur_margin
from .render.flicker_renderer import FlickerRenderer
from .render.renderer import Renderer
from .render.result import LinearFrame

DEFAULT_BOUND_PX = 0.5
MAX_SAMPLES = 512
EGO_SAMPLES = 8
"""Most samples per line when the camera moves. Every line then moves and every sample is a whole-line render
(the background shader), so the bound's count (30-200 at 1080p for the ego presets) cost seconds a frame; capped,
a frame costs at most this many renders whatever the image speed, and the plan says it is ``capped``. What the
cap costs in error against the many-sample reference is stated and tested in tests/test_sensor_path.py
(``EGO_ERROR_DN``) and docs/sensor-model.md."""
EGO_PATH_SAMPLES = 8
"""Most background samples per line of a moving camera's path blur (``plan_samples(ego_path=True)``, what the
sensor path uses): each is a bilinear read of one background render, not a render (at 1080p a frame's reads cost
about a quarter of a frame's whole-line samples, each), so with as many samples as ``EGO_SAMPLES`` a 1080p frame
costs half; the actors keep ``EGO_SAMPLES``. More reads buy less error where the image moves fast (drone) at
about 40 ms of CPU per read per 1080p frame. Its error against the many-sample reference is stated and tested in
tests/test_sensor_path.py (``PATH_ERROR_DN``) and docs/sensor-model.md."""
EGO_MARGIN_PX = 64
"""Most background rendered beyond each image edge for the path blur's reads (render px)."""
BATCH_SAMPLES = 32_768  # (line, sample) pairs per render call: bounds the per-call tables (actors x pairs)
GRID_FRACTION = 0.125
"""Largest shift of a sample by snapping to the shared time grid, in blur bounds (at the fastest image speed)."""
BOUND_LINES = 16
"""Lines per group of the plan's screen of (actor, line) pairs before their own swept bounds (``touching_lines``)."""
_SPEED_STEP_NS = 250_000  # actor speed sampling step; gait changes little within a quarter millisecond


@dataclass(frozen=True)
class SamplePlan:
    """Samples per line for one frame: ``n[line]``, the image speed behind it, and what was capped."""

    starts_ns: np.ndarray
    exposure_ns: int
    n: np.ndarray
    speed_px_s: np.ndarray
    capped: bool
    grid_ns: int = 0
    """Sample times snap to the nearest multiple of this (0: not at all), so lines share them (below)."""
    path_n: np.ndarray | None = None
    """A moving camera's background path samples per line (``Renderer.path_blur``), the actors then sampled
    ``n`` times over it; None: the whole line is rendered at each of its ``n`` samples."""
    margin_px: int = 0
    """Background rendered beyond each image edge for the path blur (render px)."""

    @property
    def evaluations(self) -> int:
        """Line evaluations the plan needs (sum of samples over lines)."""
        return int(self.n.sum())

    def times_ns(self, j: int) -> np.ndarray:
        """Per-line times of pass ``j``: sample j of each line (its last sample where it has fewer)."""
        k = np.minimum(j, self.n - 1)
        return sample_times_ns(self.starts_ns, self.exposure_ns, k, self.n, self.grid_ns)


def sample_times_ns(starts_ns: np.ndarray, exposure_ns: int, k: np.ndarray, n: np.ndarray, grid_ns: int) -> np.ndarray:
    """Sample k of n of windows starting at ``starts_ns``: the midpoint rule on integer ns, start + (2k + 1) *
    exposure / (2n), snapped to the nearest multiple of ``grid_ns`` when it is > 0.

    A rolling shutter's lines start one line time apart, so their own midpoints are all different instants and
    each needs every walker touching it posed afresh; snapped to a grid finer than the blur bound needs, the
    lines a walker crosses share its poses (the renderer computes an actor's parts once per shared instant).
    """
    t = starts_ns + ((2 * k + 1) * exposure_ns) // (2 * n)
    if grid_ns > 0:
        t = ((t + grid_ns // 2) // grid_ns) * grid_ns
    return t


def _ego_speed_px_s(renderer: Renderer, by_column: bool, t0_s: float, t1_s: float) -> float:
    rot, pos = renderer.poses(np.array([t0_s, t1_s]), by_column=by_column)
    dt = max(t1_s - t0_s, 1e-9)
    cos_a = np.clip((np.trace(rot[1] @ rot[0].T) - 1.0) / 2.0, -1.0, 1.0)
    cam = renderer.camera
    f = float(cam.fx_px)
    corner = math.hypot(float(cam.width), float(cam.height)) / (2 * f)
    rot_px_s = math.acos(cos_a) / dt * f * (1 + corner * corner)
    height_m = max(abs(float(pos[0, 2])), 1.0)
    trans_px_s = float(np.linalg.norm(pos[1] - pos[0])) / dt * f / height_m
    return rot_px_s + trans_px_s


def _swept_bounds(renderer: Renderer, by_column: bool, start_s: np.ndarray, exp_s: float, need: np.ndarray
                  ) -> np.ndarray:
    """Per actor and line, a render-space box holding the actor over that line's window.

    A static camera has one pose, so the renderer's swept bounds serve directly. A moving camera's bounds
    hold at one pose only: the hull of the boxes at the window's start and end stands in for the sweep.
    """
    n_lines = need.shape[1]
    ends = [start_s] if not renderer.camera_moving else [start_s, start_s + exp_s]
    span = np.full(n_lines, 0.0 if renderer.camera_moving else exp_s)
    out: np.ndarray | None = None
    for t in ends:
        b = renderer.actor_bounds(t, span, need, by_column=by_column)
        if out is None:
            out = b
        else:
            out[..., 0] = np.minimum(out[..., 0], b[..., 0])
            out[..., 2] = np.minimum(out[..., 2], b[..., 2])
            out[..., 1] = np.maximum(out[..., 1], b[..., 1])
            out[..., 3] = np.maximum(out[..., 3], b[..., 3])
    assert out is not None
    return out


def touching_lines(renderer: Renderer, starts_ns: np.ndarray, exposure_ns: int, *, by_column: bool = False
                   ) -> np.ndarray:
    """Which moving actor can touch which line during the line's window (``starts_ns[l]`` + [0, exposure_ns]):
    ``(actors, lines)`` bool, from the conservative swept bounds of each (actor, line) pair.

    A static camera's pairs are first screened by group: the box of an actor over a group of ``BOUND_LINES``
    consecutive lines' windows holds its box over each line's (a walker's box is its reach around the root at the
    window's start plus its speed times the window's length, so a sub-window's box lies inside), and the lines
    whose centres it misses by more than a pixel need no box of their own. The pairs left get the same per-line
    boxes as without the screen, so the result is the same; a frame of 20 walkers bounds ~1/4 of its pairs.
    """
    starts = np.asarray(starts_ns, np.int64)
    n_lines, n_along = renderer.render_shape(by_column)
    if starts.shape != (n_lines,):
        raise ConfigError(f"need one window start per line: {n_lines} lines, got shape {starts.shape}")
    start_s, exp_s, moving = starts.astype(np.float64) * 1e-9, int(exposure_ns) * 1e-9, renderer.moving_actors
    need = np.zeros((renderer.n_actors, n_lines), np.bool_)
    need[moving] = True
    if not renderer.camera_moving and n_lines > BOUND_LINES:
        first = np.arange(0, n_lines, BOUND_LINES)
        lo, hi = np.minimum.reduceat(start_s, first), np.maximum.reduceat(start_s, first)
        g_need = np.zeros((renderer.n_actors, first.size), np.bool_)
        g_need[moving] = True
        gb = renderer.actor_bounds(lo, hi - lo + exp_s, g_need, by_column=by_column)
        last = np.minimum(first + BOUND_LINES, n_lines)
        near = ((gb[..., 0] <= last + 1.0) & (gb[..., 1] >= first - 1.0) & (gb[..., 2] < n_along + 1.0)
                & (gb[..., 3] > -1.0) & g_need)
        need = np.repeat(near, last - first, axis=1)
    bounds = _swept_bounds(renderer, by_column, start_s, exp_s, need)
    centre = np.arange(n_lines) + 0.5
    return (need & (bounds[..., 0] <= centre) & (centre <= bounds[..., 1]) & (bounds[..., 2] < n_along)
            & (bounds[..., 3] > 0))


def _part_speeds(actor_px_s: float, part_rate: np.ndarray, part_y: np.ndarray, step_s: float, n_lines: int
                 ) -> np.ndarray:
    """One actor's image speed on each line (px/s): the fastest of its parts that reach the line at some time
    (``Renderer.actor_part_motion``; a part whose motion was not measured moves at the actor's speed).

    A line's blur only needs the motion of what can be on it: a walker's head and torso move at its walking speed,
    its feet and hands at two or three times that. Each part's line range is widened by one step of its motion
    (it was measured at the speed steps only) and a pixel, so the speed stays an upper bound on every line."""
    rate = np.where(part_rate < 0.0, actor_px_s, part_rate)
    shown = (part_y[:, 0] <= part_y[:, 1]) & (rate > 0.0)
    if not shown.any():
        return np.zeros(n_lines)
    rate, pad = rate[shown], rate[shown] * step_s + 1.0
    lo, hi = part_y[shown, 0] - pad, part_y[shown, 1] + pad
    centre = np.arange(n_lines) + 0.5
    on = (lo[:, None] <= centre[None, :]) & (centre[None, :] <= hi[:, None])
    return np.where(on, rate[:, None], 0.0).max(axis=0)


def plan_samples(renderer: Renderer, starts_ns: np.ndarray, exposure_ns: int, *, by_column: bool = False,
                 bound_px: float = DEFAULT_BOUND_PX, max_samples: int = MAX_SAMPLES,
                 ego_samples: int = EGO_SAMPLES, ego_path: bool = False,
                 path_samples: int = EGO_PATH_SAMPLES, part_speeds: bool = True) -> SamplePlan:
    """The adaptive plan: per line, ceil(speed * exposure / bound) samples (1 where nothing moves), at most
    ``max_samples``, and at most ``ego_samples`` when the camera moves (where that cuts a line's count, the
    bound no longer holds and the plan is ``capped``).

    ``ego_path`` (a moving camera): the static background is integrated along each pixel's image path with
    the bound's count of samples, at most ``path_samples`` (``Renderer.path_blur``), and only the actors are
    rendered at the ``n`` samples; ``capped`` then says either count was cut.

    ``part_speeds`` (a static camera): a line's speed is that of the fastest actor part that can reach it
    (``_part_speeds``), not of the fastest part of every actor touching it (False: that per-actor rule), and
    where that changes a line's speed its count is rounded up to a power of two: about 2x fewer samples on a
    street of walkers, at the error stated in docs/sensor-model.md.
    """
    starts = np.asarray(starts_ns, np.int64)
    n_lines = starts.shape[0]
    if not bound_px > 0 or not math.isfinite(bound_px):
        raise ConfigError(f"blur bound must be a finite number of pixels > 0, got {bound_px!r}")
    speed = np.zeros(n_lines)
    refined = np.zeros(n_lines, np.bool_)  # lines whose part speed differs from the per-actor rule's
    exp_s = exposure_ns * 1e-9
    ego_px_s = 0.0
    if exposure_ns > 0:
        t0, t1 = int(starts.min()), int(starts.max()) + int(exposure_ns)
        if renderer.camera_moving:
            ego_px_s = _ego_speed_px_s(renderer, by_column, t0 * 1e-9, t1 * 1e-9)
            speed[:] = ego_px_s
        moving = renderer.moving_actors
        if moving.size:
            touch = touching_lines(renderer, starts, exposure_ns, by_column=by_column)
            seen = touch.any(axis=1)  # only the actors some line can see need a speed
            n_t = max(2, -(-(t1 - t0) // _SPEED_STEP_NS) + 1)
            act_speed, part_rate, part_y = renderer.actor_part_motion(
                np.linspace(t0 * 1e-9, t1 * 1e-9, n_t), by_column=by_column, actors=seen)
            step_s = (t1 - t0) * 1e-9 / (n_t - 1)
            actor_rule = np.zeros(n_lines)
            for o in np.flatnonzero(seen):
                actor_rule[touch[o]] = np.maximum(actor_rule[touch[o]], act_speed[o])
                # A moving camera moves every line anyway (and is capped): the actor's speed will do.
                if renderer.camera_moving or not part_speeds:
                    speed[touch[o]] = np.maximum(speed[touch[o]], act_speed[o])
                    continue
                own = _part_speeds(act_speed[o], part_rate[o], part_y[o], step_s, n_lines)
                speed[touch[o]] = np.maximum(speed[touch[o]], own[touch[o]])
            if part_speeds and not renderer.camera_moving:
                refined = speed != actor_rule
    want = np.ceil(speed * exp_s / bound_px)
    cap = min(max_samples, max(int(ego_samples), 1)) if renderer.camera_moving else max_samples
    n = np.clip(np.nan_to_num(want, nan=cap, posinf=cap), 1, cap).astype(np.int64)
    # A part speed's count goes up to a power of two: few distinct counts, so neighbouring lines keep sharing the
    # grid's instants (with exact counts a small frame's lines shared fewer of them than the per-actor rule's).
    n = np.where(refined & (n > 1), np.minimum(2 ** np.ceil(np.log2(np.maximum(n, 1))).astype(np.int64), cap), n)
    # Snapping moves a sample by at most half the grid: at the fastest speed, GRID_FRACTION of the bound.
    fastest = float(speed.max()) if speed.size else 0.0
    grid = int(GRID_FRACTION * 2 * bound_px / fastest * 1e9) if fastest > 0 and math.isfinite(fastest) else 0
    capped = bool((want > cap).any())
    if not (ego_path and renderer.camera_moving and exposure_ns > 0):
        return SamplePlan(starts, int(exposure_ns), n, speed, capped, grid)
    path_cap = max(int(path_samples), 1)
    path_n = np.clip(np.nan_to_num(want, nan=path_cap, posinf=path_cap), 1, path_cap).astype(np.int64)
    # Reads reach about half a window's image path either side of the pixel (the ego speed is an upper bound).
    margin = blur_margin(ego_px_s * exp_s / 2, EGO_MARGIN_PX) if math.isfinite(ego_px_s) else EGO_MARGIN_PX
    return SamplePlan(starts, int(exposure_ns), n, speed, capped or bool((want > path_cap).any()), grid, path_n,
                      margin)


def dense_plan(plan: SamplePlan, step_px: float = 0.05) -> SamplePlan:
    """Fixed dense sampling: every line gets the samples the fastest line needs at ``step_px``, at each line's own
    midpoints (a reference: no shared grid, which would merge samples finer than it)."""
    fastest = float(plan.speed_px_s.max()) if plan.speed_px_s.size else 0.0
    n = max(1, math.ceil(fastest * plan.exposure_ns * 1e-9 / step_px))
    return SamplePlan(plan.starts_ns, plan.exposure_ns, np.full_like(plan.n, n), plan.speed_px_s, False)


@njit(cache=True, parallel=True)
def _finish(acc, static, hits, n):
    """Mean of each painted line's n samples, from ``render_linear``'s accumulator.

    Over a composite, acc holds the sum of (sample - composite) over painted samples (the others equal the
    composite): mean = composite + acc / n. Without one (moving camera) every sample was painted: acc / n.
    """
    has_static = static.shape[0] > 0
    for ln in prange(acc.shape[0]):
        if hits[ln] == 0:
            continue
        inv = np.float32(1.0 / n[ln])
        for i in range(acc.shape[1]):
            for c in range(3):
                if has_static:
                    acc[ln, i, c] = static[ln, i, c] + acc[ln, i, c] * inv
                else:
                    acc[ln, i, c] *= inv


@dataclass
class Integrated:
    """A frame integrated over its exposure windows: linear RGB radiance (time-averaged) and the cost.

    ``radiance`` holds the lines some sample painted and points at the renderer's static composite for the
    rest (every sample of such a line is the composite); ``linear`` is the whole frame as one array.
    """

    radiance: LinearFrame
    evaluations: int
    lines_painted: int
    passes: int

    @cached_property
    def linear(self) -> np.ndarray:
        """The integrated frame as a float32 ``(H, W, 3)`` array in image orientation."""
        return self.radiance.full()


def integrate(renderer: Renderer, plan: SamplePlan, *, by_column: bool = False, out: np.ndarray | None = None,
              batch_samples: int = BATCH_SAMPLES) -> Integrated:
    """Average the scene's linear radiance over each line's window with the plan's samples.

    Every (line, sample) pair a moving thing touches is rendered (``Renderer.accumulate_samples``, whole
    lines per batch), accumulating just the pixels under actors as differences from the static composite;
    the mean is composite + sum / n. Nothing copies a whole frame or even a whole line.
    ``out`` (float32, render orientation: lines x pixels per line x 3) is a reusable accumulator; the result's
    ``radiance`` keeps it, so it must not be reused while that is in use. ``batch_samples`` bounds the
    (line, sample) pairs per render call (whole lines per call; the result does not depend on it).
    """
    n_lines, n_along = renderer.render_shape(by_column)
    if plan.n.shape != (n_lines,):
        raise ConfigError(f"the plan has {plan.n.shape[0]} lines, the render {n_lines}")
    if isinstance(renderer, FlickerRenderer):
        return _integrate_lights(renderer, plan, by_column, out, batch_samples)
    shape = (n_lines, n_along, 3)
    # Fresh np.empty pages are only faulted in where a line is written, so untouched lines cost nothing.
    acc = np.empty(shape, np.float32) if out is None else out
    hits = np.zeros(n_lines, np.int64)
    passes = int(plan.n.max())
    path = plan.path_n is not None and renderer.camera_moving
    static, painted = _accumulate(renderer, plan, by_column, acc, hits, batch_samples, path)
    if path:
        assert plan.path_n is not None
        renderer.path_blur(plan.starts_ns, plan.exposure_ns, plan.path_n, plan.n, acc, hits, by_column=by_column,
                           margin=plan.margin_px)
        return Integrated(LinearFrame(None, acc, np.ones(n_lines, np.bool_), by_column), plan.evaluations, painted,
                          passes)
    _finish(acc, static if static is not None else np.empty((0, n_along, 3), np.float32), hits, plan.n)
    return Integrated(LinearFrame(static, acc, hits > 0, by_column), plan.evaluations, painted, passes)


def _accumulate(renderer: Renderer, plan: SamplePlan, by_column: bool, acc: np.ndarray, hits: np.ndarray,
                batch_samples: int, actors_only: bool) -> tuple[np.ndarray | None, int]:
    """Every (line, sample) pair of the plan through ``Renderer.accumulate_samples``, a line's samples together, in
    batches of whole lines of bounded size; returns the shared composite and the samples painted."""
    n_lines = plan.n.shape[0]
    n = plan.n.astype(np.int64)
    line_of = np.repeat(np.arange(n_lines, dtype=np.int64), n)
    first = np.cumsum(n) - n
    k = np.arange(line_of.size, dtype=np.int64) - first[line_of]
    times = sample_times_ns(plan.starts_ns[line_of], plan.exposure_ns, k, n[line_of], plan.grid_ns)
    painted = 0
    static = None
    bounds = np.searchsorted(first, np.arange(0, line_of.size, max(int(batch_samples), 1)), side="right") - 1
    cuts = np.unique(np.append(first[bounds], line_of.size))
    for a, b in pairwise(cuts.tolist()):
        static, got = renderer.accumulate_samples(times[a:b], line_of[a:b], acc, hits, by_column=by_column,
                                                  actors_only=actors_only)
        painted += got
    return static, painted


def _integrate_lights(renderer: FlickerRenderer, plan: SamplePlan, by_column: bool, out: np.ndarray | None,
                      batch_samples: int) -> Integrated:
    """Each light's render integrated with the plan, weighted per line by the light's mean over the line's
    whole window [start, start + exposure] (``rollcam.sim.render.flicker_renderer``), summed into ``out``."""
    n_lines, n_along = renderer.render_shape(by_column)
    parts = [integrate(p, plan, by_column=by_column, out=renderer.scratch(k, by_column), batch_samples=batch_samples)
             for k, p in enumerate(renderer.parts)]
    weights = renderer.line_weights(plan.starts_ns, plan.starts_ns + plan.exposure_ns)
    dst = np.empty((n_lines, n_along, 3), np.float32) if out is None else out
    renderer.join([p.radiance for p in parts], weights, np.arange(n_lines), dst)
    return Integrated(LinearFrame(None, dst, np.ones(n_lines, np.bool_), by_column),
                      sum(p.evaluations for p in parts), sum(p.lines_painted for p in parts),
                      max(p.passes for p in parts))


guard(__name__)  # after every kernel and import: see rollcam.sim._jitcache
