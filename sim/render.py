"""Per-line renderer: one scene function evaluated at a vector of line times.

``Renderer.render_lines(times_ns)`` is the core call of DESIGN.md: one sample time per image line (row, or
column for column readout). A global-shutter frame passes one time for every line; a rolling-shutter frame
``t_start + offset(r)``; a banded approximation repeats each of K times over a band of lines. The same call
backs all three, and ``reference_lines`` is the study's brute-force oracle (one full render per line time,
keeping line r of render r).

Work the scene does not need is skipped: the static world (and any actor that does not move) is rendered
once and cached; lines no moving actor touches at their own time are copied from that cache; each actor's
pose is evaluated once per distinct time it is needed at, so a static scene costs one render and a GS frame
one pose per actor.

``render_linear`` is the sensor path's call: linear radiance only (no 8-bit image), of a chosen subset of
lines, returned as a ``LinearFrame`` (the cached static composite, shared, plus the painted lines in a
reusable buffer) or accumulated into one for exposure integration. Painted lines equal ``render_lines``'s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from rollcam.common.errors import ConfigError

from . import _kernels as K
from ._paint import Painter, Pass
from .frame import Box, ObjectTruth
from .scene import Camera, Scene


def srgb_lut() -> np.ndarray:
    """8-bit sRGB encoding of linear values 0..1 sampled at LUT_SIZE + 1 points."""
    v = np.linspace(0.0, 1.0, K.LUT_SIZE + 1)
    s = np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(v, 1 / 2.4) - 0.055)
    return np.clip(np.round(s * 255.0), 0, 255).astype(np.uint8)


_SRGB = srgb_lut()


@dataclass
class LineTruth:
    """Per-actor, per-line ground truth of one render, in render space (lines x along-line position)."""

    left: np.ndarray  # (actors, lines) float64, NaN where the actor has no pixel on the line
    right: np.ndarray
    area: np.ndarray  # (actors, lines) int64: pixels whose centre the actor covers
    visible: np.ndarray  # (actors, lines) int64: of those, pixels no nearer actor hides
    transposed: bool

    @classmethod
    def empty(cls, n_actors: int, n_lines: int, transposed: bool) -> LineTruth:
        """Arrays for a render of ``n_lines`` lines."""
        return cls(
            np.full((n_actors, n_lines), np.nan),
            np.full((n_actors, n_lines), np.nan),
            np.zeros((n_actors, n_lines), np.int64),
            np.zeros((n_actors, n_lines), np.int64),
            transposed,
        )

    def boxes(self) -> list[Box | None]:
        """Image-space box of each actor: union of its per-line extents (None when it has no pixel)."""
        out: list[Box | None] = []
        has = ~np.isnan(self.left)
        for o in range(self.left.shape[0]):
            lines = np.flatnonzero(has[o])
            if lines.size == 0:
                out.append(None)
                continue
            a0 = float(np.min(self.left[o, lines]))
            a1 = float(np.max(self.right[o, lines]))
            b0, b1 = float(lines[0]), float(lines[-1] + 1)
            out.append((b0, a0, b1, a1) if self.transposed else (a0, b0, a1, b1))
        return out

    def visible_fraction(self) -> np.ndarray:
        """Fraction of each actor's in-image pixels not hidden by nearer actors (0 when none)."""
        tot = self.area.sum(axis=1)
        vis = self.visible.sum(axis=1)
        return np.where(tot > 0, vis / np.maximum(tot, 1), 0.0)


@dataclass
class RenderResult:
    """A rendered image (8-bit BGR, optionally linear RGB float32) and its per-line ground truth."""

    image: np.ndarray
    linear: np.ndarray | None
    truth: LineTruth
    lines_painted: int = 0  # lines rendered rather than copied from the static cache
    radiance: LinearFrame | None = None  # render_linear's result (image and linear are then empty/None)


@dataclass
class LinearFrame:
    """Linear RGB radiance of a frame, held as the renderer's static composite plus the lines painted over it.

    ``static`` and ``lines`` are float32 ``(lines, pixels per line, 3)`` in render orientation (rows, or
    columns when ``by_column``); line i of the frame is ``lines[i]`` where ``painted[i]``, else ``static[i]``.
    ``static`` is the renderer's cache, shared and never written (None for a moving camera, when every line is
    painted). This lets the sensor path read untouched lines in place instead of copying 25 MB per frame.
    """

    static: np.ndarray | None
    lines: np.ndarray
    painted: np.ndarray  # (lines,) bool
    by_column: bool = False

    def full(self) -> np.ndarray:
        """The whole frame as one fresh float32 ``(H, W, 3)`` array in image orientation."""
        if self.static is None:
            out = self.lines.copy()
        else:
            out = self.static.copy()
            idx = np.flatnonzero(self.painted)
            out[idx] = self.lines[idx]
        return out.transpose(1, 0, 2) if self.by_column else out


class _Layer:
    """Static layers of one camera orientation: bare background, and background with the static actors."""

    def __init__(self, bg_lin: np.ndarray | None) -> None:
        self.bg_lin = bg_lin
        self.comp_lin: np.ndarray | None = None
        self.comp_u8: np.ndarray | None = None
        self.comp_gt: np.ndarray | None = None

    def truth(self, n_actors: int, transposed: bool) -> LineTruth:
        """A fresh copy of the composite's ground truth."""
        assert self.comp_gt is not None
        gt = LineTruth.empty(n_actors, self.comp_gt.shape[2], transposed)
        gt.left[:], gt.right[:] = self.comp_gt[0], self.comp_gt[1]
        gt.area[:], gt.visible[:] = self.comp_gt[2], self.comp_gt[3]
        return gt


class Renderer:
    """Renders one camera of a scene at arbitrary per-line times, with exact per-actor ground truth.

    Four operations, one kernel (``_paint.Painter``): a frame of lines (8-bit, optionally linear),
    its ground truth only, linear radiance of chosen lines into a buffer (or accumulated, for exposure
    integration), and the brute-force reference. The sensor path's planning reads the scene through
    ``poses``, ``actor_bounds`` and ``actor_image_speeds``.
    """

    def __init__(self, scene: Scene, camera: Camera | int | str = 0, *, gain: float = 1.0) -> None:
        self.scene = scene
        self.camera = camera if isinstance(camera, Camera) else scene.camera(camera)
        if self.camera.width <= 0 or self.camera.height <= 0:
            raise ConfigError(f"camera size must be positive, got {self.camera.width}x{self.camera.height}")
        self._painter = Painter(scene, self.camera, float(gain), _SRGB)
        self._layers: dict[bool, _Layer] = {}
        self.camera_moving = self.camera.ego.moving
        tables = self._painter.tables
        self.actor_ids = tables.actor_ids
        self.actor_classes = tables.actor_classes
        self.actor_speeds_mps = tables.actor_speeds_mps
        self._all = np.ones(self.n_actors, np.bool_)

    # ------------------------------------------------------------------ the scene as the renderer sees it
    @property
    def gain(self) -> float:
        """Scale from linear radiance to the 8-bit image's encoding input."""
        return self._painter.gain

    @property
    def n_actors(self) -> int:
        """Number of actors (pedestrians, chart bars) in the scene."""
        return self._painter.n_actors

    @property
    def moving_actors(self) -> np.ndarray:
        """Indices of the actors that move in the scene (whatever the camera does)."""
        return np.flatnonzero(~self._painter.actor_static)

    def render_shape(self, by_column: bool = False) -> tuple[int, int]:
        """(lines, pixels per line) of a render: (height, width), or (width, height) by column."""
        w, h = self.camera.width, self.camera.height
        return (w, h) if by_column else (h, w)

    def poses(self, times_s: np.ndarray, *, by_column: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Camera rotation ``(n, 3, 3)`` and position ``(n, 3)`` (world to camera) at each time in seconds."""
        return self._painter.poses(by_column, np.asarray(times_s, np.float64))

    def actor_bounds(self, times_s: np.ndarray, span_s: np.ndarray, need: np.ndarray, *,
                     by_column: bool = False) -> np.ndarray:
        """Conservative render-space boxes ``(actors, n, 4)`` (ymin, ymax, xmin, xmax; empty when ymin > ymax).

        Box ``[o, i]`` holds actor o over ``times_s[i] .. times_s[i] + span_s[i]`` seen from the camera pose at
        ``times_s[i]`` (a moving camera's pose holds at that instant only); computed where ``need[o, i]``,
        unset elsewhere.
        """
        times_s = np.asarray(times_s, np.float64)
        span_s = np.asarray(span_s, np.float64)
        if need.shape != (self.n_actors, times_s.shape[0]) or span_s.shape != times_s.shape:
            raise ConfigError(f"need must be (actors, times) = {(self.n_actors, times_s.shape[0])} and span one per "
                              f"time, got {need.shape} and {span_s.shape}")
        rot, pos = self.poses(times_s, by_column=by_column)
        return self._painter.bounds(self._painter.cams[by_column], rot, pos, times_s,
                                    np.arange(times_s.shape[0]), span_s, need)

    def actor_image_speeds(self, times_s: np.ndarray, *, by_column: bool = False) -> np.ndarray:
        """Per actor, the fastest render-space displacement rate (px/s) of its parts between consecutive times.

        Parts wholly off the image by more than half its size are ignored (see ``_actors.actor_speeds``);
        a chart bar's rate is its speed.
        """
        return self._painter.speeds(by_column, np.asarray(times_s, np.float64))

    def actor_parts(self, times_s: np.ndarray, *, by_column: bool = False) -> np.ndarray:
        """The render-space primitives the kernels draw: ``(actors, times, MAX_PARTS, PART_COLS)`` float64.

        Row layout in ``rollcam.sim._actors`` (``Q_KIND`` capsule, quad or none; geometry from ``Q_GEO``;
        line range ``Q_YMIN``..``Q_YMAX``). For checks and studies; a render computes only the parts it needs.
        """
        return self._painter.parts(by_column, np.asarray(times_s, np.float64))

    # ------------------------------------------------------------------ frames
    def render_lines(
        self,
        times_ns: np.ndarray,
        *,
        by_column: bool = False,
        linear: bool = False,
        truth_only: bool = False,
    ) -> RenderResult:
        """Render every image line at its own time (``times_ns``: int64, one per row or per column).

        Returns the 8-bit BGR image in image orientation, the linear RGB float32 image when ``linear``,
        and the per-line ground truth. ``truth_only`` skips pixels (for boxes at another instant).
        """
        n_along = self.render_shape(by_column)[1]
        times_ns = self._check_times(times_ns, by_column)
        ut_ns, line_k = np.unique(times_ns, return_inverse=True)
        times_s = ut_ns.astype(np.float64) * 1e-9
        layer = self._layer(by_column, times_s[0])
        p = self._painter.prepare(by_column, times_s, line_k.astype(np.int64), self._all, n_along)
        if truth_only:
            return self._truth(p, layer, by_column)
        return self._frame(p, layer, by_column, linear)

    def render_linear(
        self,
        times_ns: np.ndarray,
        *,
        by_column: bool = False,
        lines: np.ndarray | None = None,
        out: np.ndarray | None = None,
        hits: np.ndarray | None = None,
    ) -> RenderResult:
        """Linear radiance only, of the ``lines`` asked for (bool mask or indices; all when None).

        No 8-bit image and no copy of the static composite: the result's ``radiance`` (a ``LinearFrame``)
        holds the painted lines in ``out`` (a reusable float32 buffer in render orientation, or a fresh one)
        and points at the cached composite for the rest. Lines not asked for are neither painted nor valid.
        Painted lines equal ``render_lines(..., linear=True)``'s exactly, and so does ``truth`` on the lines
        asked for (other lines hold the static composite's truth).

        With ``hits`` (int64, one count per line) ``out`` accumulates instead, for exposure integration:
        ``hits`` counts each line's painted renders and ``out`` holds the sum of (painted line - composite)
        over them (zeroed on a line's first hit; only pixels under actors are touched after), or for a
        moving camera (``radiance.static`` None) the sum of the painted lines.
        """
        n_lines, n_along = self.render_shape(by_column)
        times_ns = self._check_times(times_ns, by_column)
        subset = self._line_mask(lines, n_lines)
        if out is None:
            out = np.empty((n_lines, n_along, 3), np.float32)
        self._check_buffers(out, hits, by_column)
        # Only the asked-for lines' times are posed and bounded (a pass of an exposure needs few lines).
        sub_idx = np.flatnonzero(subset)
        ut_ns, sub_k = np.unique(times_ns[sub_idx] if sub_idx.size else times_ns[:1], return_inverse=True)
        line_k = np.zeros(n_lines, np.int64)
        line_k[sub_idx] = sub_k
        times_s = ut_ns.astype(np.float64) * 1e-9
        layer = self._layer(by_column, float(times_ns.min()) * 1e-9)
        p = self._painter.prepare(by_column, times_s, line_k, self._all, n_along, only=sub_idx)
        return self._linear_into(p, layer, by_column, subset, out, hits)

    def accumulate_samples(self, times_ns: np.ndarray, line_of: np.ndarray, out: np.ndarray, hits: np.ndarray,
                           *, by_column: bool = False) -> tuple[np.ndarray | None, int]:
        """Render many (line, time) samples in one go and accumulate them, as ``render_linear(hits=...)`` does.

        Sample e is line ``line_of[e]`` (non-decreasing: a line's samples together) at ``times_ns[e]``. Each
        painted sample is added to ``out`` (render orientation) as its difference from the static composite
        (or whole, for a moving camera) and counted in ``hits``; samples no actor pixel lands on are the
        composite and skipped. One call instead of one per sample index saves the per-call set-up that
        dominates many-pass exposures. Returns the shared composite (None for a moving camera) and the
        number of samples painted. Ground truth is not produced.
        """
        n_lines, n_along = self.render_shape(by_column)
        times_ns = np.asarray(times_ns, np.int64)
        line_of = np.asarray(line_of, np.int64)
        n_ent = times_ns.shape[0]
        if line_of.shape != (n_ent,) or (n_ent and (line_of[0] < 0 or line_of[-1] >= n_lines
                                                    or (np.diff(line_of) < 0).any())):
            raise ConfigError(f"line_of must hold one non-decreasing line index in 0..{n_lines - 1} per sample")
        self._check_buffers(out, hits, by_column, need_hits=True)
        layer = self._layer(by_column, float(times_ns.min()) * 1e-9 if n_ent else 0.0)
        shared = None if self.camera_moving else _read_only(layer.comp_lin)
        if n_ent == 0:
            return shared, 0
        ut_ns, ent_k = np.unique(times_ns, return_inverse=True)
        p = self._painter.prepare(by_column, ut_ns.astype(np.float64) * 1e-9, ent_k.astype(np.int64), self._all,
                                  n_along, line_of=line_of)
        # A moving camera changes every sample; over a composite only samples an actor touches differ from it.
        ents = np.arange(n_ent) if self.camera_moving else np.flatnonzero(p.touched(self._all))
        lines, first = np.unique(line_of[ents], return_index=True)
        gt = LineTruth.empty(self.n_actors, n_lines, by_column)  # scratch for the kernel
        before = int(hits.sum())
        self._painter.paint(p, self._all, lines.astype(np.int64), gt, bg=layer.bg_lin, out_lin=out,
                            full_lines=self.camera_moving, seed=None if self.camera_moving else layer.comp_lin,
                            hits=hits, e_start=np.append(first, ents.size).astype(np.int64), ents=ents)
        return shared, int(hits.sum()) - before

    def reference_frame(self, t_ns: int, *, by_column: bool = False) -> RenderResult:
        """One full render with every line at ``t_ns`` and no shortcuts: every line painted over the bare
        background with every actor tested against it (no static-actor composite, no touched-line culling).
        """
        n_lines, n_along = self.render_shape(by_column)
        t_s = np.array([np.int64(t_ns).astype(np.float64) * 1e-9])
        layer = self._layer(by_column, t_s[0])
        p = self._painter.prepare(by_column, t_s, np.zeros(n_lines, np.int64), self._all, n_along, exhaustive=True)
        u8, _, gt = self._whole(p, layer, self._all, by_column, linear=False)
        return RenderResult(_oriented(u8, by_column, contiguous=True), None, gt, n_lines)

    def reference_lines(self, times_ns: np.ndarray, *, by_column: bool = False) -> RenderResult:
        """The study's brute-force method: one full render per line, keeping line r of render r.

        Each full render is ``reference_frame``, which shares only the bare background with the fast path,
        so the fast path's caches and culling are checked against it, not assumed.
        """
        times_ns = self._check_times(times_ns, by_column)
        n_lines = times_ns.shape[0]
        out: RenderResult | None = None
        for r in range(n_lines):
            full = self.reference_frame(int(times_ns[r]), by_column=by_column)
            if out is None:
                out = RenderResult(np.empty_like(full.image), None,
                                   LineTruth.empty(self.n_actors, n_lines, by_column))
            if by_column:
                out.image[:, r] = full.image[:, r]
            else:
                out.image[r] = full.image[r]
            for name in ("left", "right", "area", "visible"):
                getattr(out.truth, name)[:, r] = getattr(full.truth, name)[:, r]
        assert out is not None
        return out

    def object_truth(self, frame_truth: LineTruth, reference_time_ns: int, by_column: bool = False,
                     gs_truth: LineTruth | None = None) -> tuple[ObjectTruth, ...]:
        """Per-object ground truth of a frame: RS boxes from ``frame_truth``, GS boxes at the reference time.

        Objects with no pixel under either shutter are left out.
        """
        if gs_truth is None:
            n_lines = self.render_shape(by_column)[0]
            gs_truth = self.render_lines(np.full(n_lines, reference_time_ns, np.int64), by_column=by_column,
                                         truth_only=True).truth
        rs_boxes = frame_truth.boxes()
        gs_boxes = gs_truth.boxes()
        vis = frame_truth.visible_fraction()
        out = []
        for o in range(self.n_actors):
            if rs_boxes[o] is None and gs_boxes[o] is None:
                continue
            out.append(ObjectTruth(self.actor_ids[o], self.actor_classes[o], gs_boxes[o], rs_boxes[o],
                                   float(vis[o]), float(self.actor_speeds_mps[o])))
        return tuple(out)

    # ------------------------------------------------------------------ the four operations
    def _whole(self, p: Pass, layer: _Layer, include: np.ndarray, by_column: bool, linear: bool
               ) -> tuple[np.ndarray, np.ndarray | None, LineTruth]:
        """Every line painted whole, over the cached background (or the background at each line's pose,
        for a moving camera): 8-bit, linear when asked, and truth, in render orientation."""
        n_lines, n_along = self.render_shape(by_column)
        u8 = np.empty((n_lines, n_along, 3), np.uint8)
        lin = np.empty((n_lines, n_along, 3), np.float32) if linear else None
        gt = LineTruth.empty(self.n_actors, n_lines, by_column)
        self._painter.paint(p, include, np.arange(n_lines), gt, bg=layer.bg_lin, out_u8=u8, out_lin=lin,
                            full_lines=True)
        return u8, lin, gt

    def _frame(self, p: Pass, layer: _Layer, by_column: bool, linear: bool) -> RenderResult:
        """A frame: whole lines for a moving camera, else the composite with the touched lines repainted."""
        if self.camera_moving:
            u8, lin, gt = self._whole(p, layer, self._all, by_column, linear)
            painted = u8.shape[0]
        else:
            # Start from the cached composite (one memcpy) and repaint only lines a moving actor touches.
            assert layer.comp_u8 is not None and layer.comp_lin is not None
            lines = np.flatnonzero(p.touched(self._all))
            u8 = layer.comp_u8.copy()
            lin = layer.comp_lin.copy() if linear else None
            gt = layer.truth(self.n_actors, by_column)
            self._painter.paint(p, self._all, lines, gt, bg=layer.bg_lin, out_u8=u8, out_lin=lin, full_lines=False)
            painted = int(lines.size)
        lin_out = None if lin is None else _oriented(lin, by_column, contiguous=False)
        return RenderResult(_oriented(u8, by_column, contiguous=True), lin_out, gt, painted)

    def _truth(self, p: Pass, layer: _Layer, by_column: bool) -> RenderResult:
        """Ground truth only: every line for a moving camera, else the composite's with touched lines redone."""
        n_lines = self.render_shape(by_column)[0]
        if self.camera_moving:
            lines, gt = np.arange(n_lines), LineTruth.empty(self.n_actors, n_lines, by_column)
        else:
            lines, gt = np.flatnonzero(p.touched(self._all)), layer.truth(self.n_actors, by_column)
        self._painter.paint(p, self._all, lines, gt, bg=layer.bg_lin, full_lines=self.camera_moving, gt_only=True)
        return RenderResult(np.empty((0, 0, 3), np.uint8), None, gt, int(lines.size))

    def _linear_into(self, p: Pass, layer: _Layer, by_column: bool, subset: np.ndarray, out: np.ndarray,
                     hits: np.ndarray | None) -> RenderResult:
        """Linear-only render of the ``subset`` lines into ``out``: the asked-for lines a moving actor touches
        (all of them for a moving camera), each seeded from the composite in the kernel; no 8-bit image."""
        n_lines = subset.shape[0]
        if self.camera_moving:
            lines, gt, seed = np.flatnonzero(subset), LineTruth.empty(self.n_actors, n_lines, by_column), None
        else:
            assert layer.comp_lin is not None
            lines = np.flatnonzero(p.touched(self._all) & subset)
            gt, seed = layer.truth(self.n_actors, by_column), layer.comp_lin
        painted = np.zeros(n_lines, np.bool_)
        self._painter.paint(p, self._all, lines, gt, bg=layer.bg_lin, out_lin=out, full_lines=self.camera_moving,
                            seed=seed, hits=hits, line_hit=painted)
        frame = LinearFrame(None if seed is None else _read_only(seed), out, painted, by_column)
        return RenderResult(np.empty((0, 0, 3), np.uint8), None, gt, int(painted.sum()), frame)

    # ------------------------------------------------------------------ internals
    def _layer(self, by_column: bool, t0_s: float) -> _Layer:
        """Static layers for this orientation, built on first use (nothing to cache for a moving camera)."""
        layer = self._layers.get(by_column)
        if layer is not None:
            return layer
        if self.camera_moving:
            layer = _Layer(None)
        else:
            n_lines, n_along = self.render_shape(by_column)
            bg = np.empty((n_lines, n_along, 3), np.float32)
            self._painter.background(by_column, t0_s, bg)
            layer = _Layer(bg)
            static = self._painter.actor_static
            p = self._painter.prepare(by_column, np.array([t0_s]), np.zeros(n_lines, np.int64), static, n_along)
            layer.comp_u8, layer.comp_lin, gt = self._whole(p, layer, static, by_column, linear=True)
            layer.comp_gt = np.stack([gt.left, gt.right, gt.area.astype(np.float64), gt.visible.astype(np.float64)])
        self._layers[by_column] = layer
        return layer

    def _check_times(self, times_ns: np.ndarray, by_column: bool) -> np.ndarray:
        n_lines = self.render_shape(by_column)[0]
        times_ns = np.asarray(times_ns, dtype=np.int64)
        if times_ns.shape != (n_lines,):
            raise ConfigError(f"need one time per line: {n_lines} lines, got times of shape {times_ns.shape}")
        return times_ns

    @staticmethod
    def _line_mask(lines: np.ndarray | None, n_lines: int) -> np.ndarray:
        """A bool mask of the asked-for lines (a mask, indices, or None for all)."""
        if lines is None:
            return np.ones(n_lines, np.bool_)
        lines = np.asarray(lines)
        if lines.dtype == np.bool_:
            if lines.shape != (n_lines,):
                raise ConfigError(f"line mask must have {n_lines} entries, got shape {lines.shape}")
            return lines
        if lines.size and (lines.min() < 0 or lines.max() >= n_lines):
            raise ConfigError(f"line indices must be in 0..{n_lines - 1}")
        subset = np.zeros(n_lines, np.bool_)
        subset[lines.astype(np.int64)] = True
        return subset

    def _check_buffers(self, out: np.ndarray, hits: np.ndarray | None, by_column: bool,
                       need_hits: bool = False) -> None:
        n_lines, n_along = self.render_shape(by_column)
        if out.shape != (n_lines, n_along, 3) or out.dtype != np.float32 or not out.flags.c_contiguous:
            raise ConfigError(f"out must be a C-contiguous float32 array of shape {(n_lines, n_along, 3)}, "
                              f"got {out.dtype} {out.shape}")
        if (hits is not None or need_hits) and (hits is None or hits.shape != (n_lines,) or hits.dtype != np.int64):
            got = None if hits is None else f"{hits.dtype} {hits.shape}"
            raise ConfigError(f"hits must be an int64 array of {n_lines} counts, got {got}")


def _oriented(a: np.ndarray, by_column: bool, *, contiguous: bool) -> np.ndarray:
    """A render-orientation array in image orientation (columns back to columns)."""
    a = a.transpose(1, 0, 2) if by_column else a
    return np.ascontiguousarray(a) if contiguous else a


def _read_only(a: np.ndarray | None) -> np.ndarray | None:
    """A read-only view: the renderer's cache, which readers must not write through."""
    if a is None:
        return None
    v = a.view()
    v.flags.writeable = False
    return v
