"""Renders over the per-line renderer's static layers: frames, ground truth only, linear radiance, accumulation.

A static camera's world, and every actor that does not move, is rendered once per orientation into a
``StaticLayer`` (the cached composite); a frame is that composite with the lines a moving actor touches
repainted, and linear-only renders and exposure integration paint just those lines over it. A moving camera has
nothing to cache, so every line is painted whole. ``Compositor`` does this for the passes that
``paint.Painter`` prepares; ``renderer.Renderer`` decides which pass a call needs.
"""

from __future__ import annotations

import numpy as np

from .paint import Painter, Pass
from .result import LinearFrame, LineTruth, RenderResult


class StaticLayer:
    """Static layers of one camera orientation: bare background, and background with the static actors."""

    def __init__(self, bg_lin: np.ndarray | None, comp_u8: np.ndarray | None = None,
                 comp_lin: np.ndarray | None = None, comp_gt: np.ndarray | None = None) -> None:
        self.bg_lin = bg_lin
        self.comp_u8 = comp_u8
        self.comp_lin = comp_lin
        self.comp_gt = comp_gt

    def truth(self, n_actors: int, transposed: bool) -> LineTruth:
        """A fresh copy of the composite's ground truth."""
        assert self.comp_gt is not None
        gt = LineTruth.empty(n_actors, self.comp_gt.shape[2], transposed)
        gt.left[:], gt.right[:] = self.comp_gt[0], self.comp_gt[1]
        gt.area[:], gt.visible[:] = self.comp_gt[2], self.comp_gt[3]
        return gt


class StaticLayers:
    """The static-layer cache of one scene camera: a layer per orientation, built on first use, never written
    after (a moving camera's layer is empty: nothing holds still in its view)."""

    def __init__(self, painter: Painter) -> None:
        self._painter = painter
        self._layers: dict[bool, StaticLayer] = {}

    def get(self, by_column: bool, t0_s: float) -> StaticLayer:
        """The layer of this orientation, built at time ``t0_s`` if it is the first use."""
        layer = self._layers.get(by_column)
        if layer is None:
            layer = self._layers[by_column] = self._build(by_column, t0_s)
        return layer

    def _build(self, by_column: bool, t0_s: float) -> StaticLayer:
        painter = self._painter
        if painter.camera_moving:
            return StaticLayer(None)
        n_lines, n_along = painter.shape(by_column)
        bg = np.empty((n_lines, n_along, 3), np.float32)
        painter.background(by_column, t0_s, bg)
        static = painter.actor_static
        p = painter.prepare(by_column, np.array([t0_s]), np.zeros(n_lines, np.int64), static, n_along)
        u8, lin, gt = painter.whole(p, static, bg, by_column, linear=True)
        comp_gt = np.stack([gt.left, gt.right, gt.area.astype(np.float64), gt.visible.astype(np.float64)])
        return StaticLayer(bg, u8, lin, comp_gt)


class Compositor:
    """Every render of one scene camera, from a prepared ``Pass`` over the static layer of its orientation."""

    def __init__(self, painter: Painter) -> None:
        self._painter = painter
        self.layers = StaticLayers(painter)
        self._moving = painter.camera_moving
        self._all = np.ones(painter.n_actors, np.bool_)

    def shared(self, layer: StaticLayer) -> np.ndarray | None:
        """The composite as readers may share it (read-only; None for a moving camera)."""
        return None if self._moving else _read_only(layer.comp_lin)

    def frame(self, p: Pass, layer: StaticLayer, by_column: bool, linear: bool) -> RenderResult:
        """A frame: whole lines for a moving camera, else the composite with the touched lines repainted."""
        painter = self._painter
        if self._moving:
            u8, lin, gt = painter.whole(p, self._all, layer.bg_lin, by_column, linear)
            painted = u8.shape[0]
        else:
            # Start from the cached composite (one memcpy) and repaint only lines a moving actor touches.
            assert layer.comp_u8 is not None and layer.comp_lin is not None
            lines = np.flatnonzero(p.touched(self._all))
            u8 = layer.comp_u8.copy()
            lin = layer.comp_lin.copy() if linear else None
            gt = layer.truth(painter.n_actors, by_column)
            painter.paint(p, self._all, lines, gt, bg=layer.bg_lin, out_u8=u8, out_lin=lin, full_lines=False)
            painted = int(lines.size)
        lin_out = None if lin is None else _oriented(lin, by_column, contiguous=False)
        return RenderResult(_oriented(u8, by_column, contiguous=True), lin_out, gt, painted)

    def truth(self, p: Pass, layer: StaticLayer, by_column: bool) -> RenderResult:
        """Ground truth only, of the lines some actor's bounds reach: over empty truth for a moving camera (every
        actor moves in its view), else over the composite's. No pixel is shaded, so a moving camera's truth
        costs its actors' touches, not a whole-frame pass."""
        n_actors, n_lines = self._painter.n_actors, self._painter.shape(by_column)[0]
        lines = np.flatnonzero(p.touched(self._all))
        gt = LineTruth.empty(n_actors, n_lines, by_column) if self._moving else layer.truth(n_actors, by_column)
        self._painter.paint(p, self._all, lines, gt, bg=layer.bg_lin, full_lines=False, gt_only=True)
        return RenderResult(np.empty((0, 0, 3), np.uint8), None, gt, int(lines.size))

    def linear_into(self, p: Pass, layer: StaticLayer, by_column: bool, subset: np.ndarray, out: np.ndarray,
                    hits: np.ndarray | None) -> RenderResult:
        """Linear-only render of the ``subset`` lines into ``out``: the asked-for lines a moving actor touches
        (all of them for a moving camera), each seeded from the composite in the kernel; no 8-bit image."""
        n_actors, n_lines = self._painter.n_actors, subset.shape[0]
        if self._moving:
            lines, gt, seed = np.flatnonzero(subset), LineTruth.empty(n_actors, n_lines, by_column), None
        else:
            assert layer.comp_lin is not None
            lines = np.flatnonzero(p.touched(self._all) & subset)
            gt, seed = layer.truth(n_actors, by_column), layer.comp_lin
        painted = np.zeros(n_lines, np.bool_)
        self._painter.paint(p, self._all, lines, gt, bg=layer.bg_lin, out_lin=out, full_lines=self._moving,
                            seed=seed, hits=hits, line_hit=painted)
        frame = LinearFrame(None if seed is None else _read_only(seed), out, painted, by_column)
        return RenderResult(np.empty((0, 0, 3), np.uint8), None, gt, int(painted.sum()), frame)

    def accumulate(self, p: Pass, layer: StaticLayer, line_of: np.ndarray, out: np.ndarray, hits: np.ndarray,
                   by_column: bool, actors_only: bool = False) -> tuple[np.ndarray | None, int]:
        """Paint and accumulate the pass's samples (entry e is line ``line_of[e]``) into ``out`` and ``hits``;
        returns the shared composite and the number of samples painted. ``actors_only`` (a moving camera): only
        what the actors add to the background at each sample's pose, under their spans."""
        whole = self._moving and not actors_only
        # A moving camera changes every sample; over a composite only samples an actor touches differ from it.
        ents = np.arange(line_of.shape[0]) if whole else np.flatnonzero(p.touched(self._all))
        lines, first = np.unique(line_of[ents], return_index=True)
        gt = LineTruth.empty(self._painter.n_actors, self._painter.shape(by_column)[0], by_column)  # kernel scratch
        before = int(hits.sum())
        self._painter.paint(p, self._all, lines.astype(np.int64), gt, bg=layer.bg_lin, out_lin=out,
                            full_lines=whole, seed=None if self._moving else layer.comp_lin, hits=hits,
                            e_start=np.append(first, ents.size).astype(np.int64), ents=ents)
        return self.shared(layer), int(hits.sum()) - before

    def reference(self, p: Pass, layer: StaticLayer, by_column: bool, linear: bool = False) -> RenderResult:
        """Every line of an exhaustive pass painted whole over the bare background (the oracle's frame)."""
        u8, lin, gt = self._painter.whole(p, self._all, layer.bg_lin, by_column, linear=linear)
        lin_out = None if lin is None else _oriented(lin, by_column, contiguous=False)
        return RenderResult(_oriented(u8, by_column, contiguous=True), lin_out, gt, u8.shape[0])


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
