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

from . import _body as B
from . import _kernels as K
from . import _world as Wd
from .render import LinearFrame, Renderer

DEFAULT_BOUND_PX = 0.5
MAX_SAMPLES = 512
BATCH_SAMPLES = 32_768  # (line, sample) pairs per render call: bounds the per-call tables (actors x pairs)
_SPEED_STEP_NS = 250_000  # actor speed sampling step; gait changes little within a quarter millisecond


@njit(cache=True, inline="always")
def _clamped(v, lo, hi):
    return min(max(v, lo), hi)


@njit(cache=True)
def _actor_speeds(actors, world, lut, bld, light, cam, rot_tab, pos_tab, times, out):
    """out[o] = fastest render-space displacement rate (px/s) of any part end point of actor o.

    Parts wholly off the image (beyond half its size) at both times cannot move a pixel and are skipped;
    end points are clamped to that margin, so a part clipped at the camera's near plane (whose clipped end
    point races across image space far outside the frame) counts only its motion near the image.
    """
    w, h = cam[Wd.C_W], cam[Wd.C_H]
    if cam[Wd.C_TRANSPOSED] != 0.0:
        w, h = h, w
    x_lo, x_hi, y_lo, y_hi = -0.5 * w, 1.5 * w, -0.5 * h, 1.5 * h
    scratch = K.parts_scratch()
    pa = np.empty((K.MAX_PARTS, K.PART_COLS))
    pb = np.empty((K.MAX_PARTS, K.PART_COLS))
    g = K.Q_GEO
    for o in range(actors.shape[0]):
        best = 0.0
        if int(actors[o, B.A_TYPE]) == B.TYPE_BAR:
            out[o] = abs(actors[o, B.R_VX])
            continue
        if not actors[o, B.P_H] > 0.0:  # a zero-size walker shows no pixel (and has no stride to walk by)
            out[o] = 0.0
            continue
        K.actor_parts(actors[o], world, lut, bld, light, cam, rot_tab[0], pos_tab[0], times[0], pa, scratch)
        for k in range(1, times.shape[0]):
            K.actor_parts(actors[o], world, lut, bld, light, cam, rot_tab[k], pos_tab[k], times[k], pb, scratch)
            dt = times[k] - times[k - 1]
            for p in range(K.MAX_PARTS):
                if pa[p, K.Q_KIND] != K.PART_CAPSULE or pb[p, K.Q_KIND] != K.PART_CAPSULE:
                    continue
                off = True
                for q in (pa, pb):
                    r = q[p, g + 4]
                    if not (max(q[p, g], q[p, g + 2]) + r < x_lo or min(q[p, g], q[p, g + 2]) - r > x_hi
                            or q[p, K.Q_YMAX] < y_lo or q[p, K.Q_YMIN] > y_hi):
                        off = False
                if off:
                    continue
                c = np.empty(8)
                for i in range(2):
                    c[4 * i] = _clamped(pa[p, g + 2 * i], x_lo, x_hi)
                    c[4 * i + 1] = _clamped(pa[p, g + 2 * i + 1], y_lo, y_hi)
                    c[4 * i + 2] = _clamped(pb[p, g + 2 * i], x_lo, x_hi)
                    c[4 * i + 3] = _clamped(pb[p, g + 2 * i + 1], y_lo, y_hi)
                da = math.hypot(c[2] - c[0], c[3] - c[1])
                db = math.hypot(c[6] - c[4], c[7] - c[5])
                d = max(da, db) + abs(pb[p, g + 4] - pa[p, g + 4])
                best = max(best, d / dt)
            pa, pb = pb, pa
        out[o] = best


@dataclass(frozen=True)
class SamplePlan:
    """Samples per line for one frame: ``n[line]``, the image speed behind it, and what was capped."""

    starts_ns: np.ndarray
    exposure_ns: int
    n: np.ndarray
    speed_px_s: np.ndarray
    capped: bool

    @property
    def evaluations(self) -> int:
        """Line evaluations the plan needs (sum of samples over lines)."""
        return int(self.n.sum())

    def times_ns(self, j: int) -> np.ndarray:
        """Per-line times of pass ``j``: sample j of each line (its last sample where it has fewer)."""
        k = np.minimum(j, self.n - 1)
        # Midpoint rule on integer ns: sample k of n sits at start + (2k + 1) * exposure / (2n).
        return self.starts_ns + ((2 * k + 1) * self.exposure_ns) // (2 * self.n)


def _ego_speed_px_s(renderer: Renderer, by_column: bool, t0_s: float, t1_s: float) -> float:
    cam = renderer._cams[by_column]
    times = np.array([t0_s, t1_s])
    rot, pos = np.empty((2, 3, 3)), np.empty((2, 3))
    Wd.pose_table(cam, times, rot, pos)
    dt = max(t1_s - t0_s, 1e-9)
    cos_a = np.clip((np.trace(rot[1] @ rot[0].T) - 1.0) / 2.0, -1.0, 1.0)
    f = max(cam[Wd.C_FX], cam[Wd.C_FY])
    corner = math.hypot(cam[Wd.C_W], cam[Wd.C_H]) / (2 * f)
    rot_px_s = math.acos(cos_a) / dt * f * (1 + corner * corner)
    height_m = max(abs(float(pos[0, 2])), 1.0)
    trans_px_s = float(np.linalg.norm(pos[1] - pos[0])) / dt * f / height_m
    return rot_px_s + trans_px_s


def _swept_bounds(renderer: Renderer, cam: np.ndarray, start_s: np.ndarray, exp_s: float, need: np.ndarray
                  ) -> np.ndarray:
    """Per actor and line, a render-space box holding the actor over that line's window.

    A static camera has one pose, so the renderer's swept bounds serve directly. A moving camera's bounds
    hold at one pose only: the hull of the boxes at the window's start and end stands in for the sweep.
    """
    n_obj, n_lines = need.shape
    ks = np.arange(n_lines)
    ends = [start_s] if not renderer.camera_moving else [start_s, start_s + exp_s]
    span = np.full(n_lines, 0.0 if renderer.camera_moving else exp_s)
    out: np.ndarray | None = None
    for t in ends:
        rot, pos = np.empty((n_lines, 3, 3)), np.empty((n_lines, 3))
        Wd.pose_table(cam, t, rot, pos)
        b = np.empty((n_obj, n_lines, 4))
        K.actor_bounds_all(renderer._c.actors, renderer._c.world, cam, rot, pos, t, ks, span, need, b)
        if out is None:
            out = b
        else:
            out[..., 0] = np.minimum(out[..., 0], b[..., 0])
            out[..., 2] = np.minimum(out[..., 2], b[..., 2])
            out[..., 1] = np.maximum(out[..., 1], b[..., 1])
            out[..., 3] = np.maximum(out[..., 3], b[..., 3])
    assert out is not None
    return out


def plan_samples(renderer: Renderer, starts_ns: np.ndarray, exposure_ns: int, *, by_column: bool = False,
                 bound_px: float = DEFAULT_BOUND_PX, max_samples: int = MAX_SAMPLES) -> SamplePlan:
    """The adaptive plan: per line, ceil(speed * exposure / bound) samples (1 where nothing moves)."""
    starts = np.asarray(starts_ns, np.int64)
    n_lines = starts.shape[0]
    if not bound_px > 0 or not math.isfinite(bound_px):
        from rollcam.common.errors import ConfigError

        raise ConfigError(f"blur bound must be a finite number of pixels > 0, got {bound_px!r}")
    speed = np.zeros(n_lines)
    exp_s = exposure_ns * 1e-9
    if exposure_ns > 0:
        t0, t1 = int(starts.min()), int(starts.max()) + int(exposure_ns)
        c, cam = renderer._c, renderer._cams[by_column]
        if renderer.camera_moving:
            speed[:] = _ego_speed_px_s(renderer, by_column, t0 * 1e-9, t1 * 1e-9)
        moving = np.flatnonzero(c.actors[:, B.A_STATIC] == 0.0) if renderer.n_actors else np.zeros(0, np.int64)
        if moving.size:
            n_t = max(2, -(-(t1 - t0) // _SPEED_STEP_NS) + 1)
            times = np.linspace(t0 * 1e-9, t1 * 1e-9, n_t)
            rot, pos = np.empty((n_t, 3, 3)), np.empty((n_t, 3))
            Wd.pose_table(cam, times, rot, pos)
            act_speed = np.zeros(c.actors.shape[0])
            _actor_speeds(c.actors, c.world, c.building_lut, c.buildings, c.light, cam, rot, pos, times, act_speed)
            # Lines each actor can touch during each line's window (conservative swept bounds).
            start_s = starts.astype(np.float64) * 1e-9
            need = np.zeros((c.actors.shape[0], n_lines), np.bool_)
            need[moving] = True
            bounds = _swept_bounds(renderer, cam, start_s, exp_s, need)
            n_along = renderer.camera.height if by_column else renderer.camera.width
            centre = np.arange(n_lines) + 0.5
            for o in moving:
                b = bounds[o]
                touch = (b[:, 0] <= centre) & (centre <= b[:, 1]) & (b[:, 2] < n_along) & (b[:, 3] > 0)
                speed[touch] = np.maximum(speed[touch], act_speed[o])
    want = np.ceil(speed * exp_s / bound_px)
    n = np.clip(np.nan_to_num(want, nan=max_samples, posinf=max_samples), 1, max_samples).astype(np.int64)
    return SamplePlan(starts, int(exposure_ns), n, speed, bool((want > max_samples).any()))


def dense_plan(plan: SamplePlan, step_px: float = 0.05) -> SamplePlan:
    """Fixed dense sampling: every line gets the samples the fastest line needs at ``step_px``."""
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
    n_lines = plan.n.shape[0]
    n_along = renderer.camera.height if by_column else renderer.camera.width
    shape = (n_lines, n_along, 3)
    # Fresh np.empty pages are only faulted in where a line is written, so untouched lines cost nothing.
    acc = np.empty(shape, np.float32) if out is None else out
    hits = np.zeros(n_lines, np.int64)
    passes = int(plan.n.max())
    # Every (line, sample) pair, a line's samples together, in batches of whole lines of bounded size.
    n = plan.n.astype(np.int64)
    line_of = np.repeat(np.arange(n_lines, dtype=np.int64), n)
    first = np.cumsum(n) - n
    k = np.arange(line_of.size, dtype=np.int64) - first[line_of]
    # Midpoint rule on integer ns, as SamplePlan.times_ns: sample k of n at start + (2k + 1) exposure / (2n).
    times = plan.starts_ns[line_of] + ((2 * k + 1) * plan.exposure_ns) // (2 * n[line_of])
    painted = 0
    static = None
    bounds = np.searchsorted(first, np.arange(0, line_of.size, max(int(batch_samples), 1)), side="right") - 1
    cuts = np.unique(np.append(first[bounds], line_of.size))
    for a, b in pairwise(cuts.tolist()):
        static, got = renderer.accumulate_samples(times[a:b], line_of[a:b], acc, hits, by_column=by_column)
        painted += got
    _finish(acc, static if static is not None else np.empty((0, n_along, 3), np.float32), hits, n)
    return Integrated(LinearFrame(static, acc, hits > 0, by_column), plan.evaluations, painted, passes)
