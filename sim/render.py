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

from . import _body as B
from . import _kernels as K
from . import _world as Wd
from .compile import compile_camera, compile_scene
from .frame import Box, ObjectTruth
from .scene import Camera, Scene


def srgb_lut() -> np.ndarray:
    """8-bit sRGB encoding of linear values 0..1 sampled at LUT_SIZE + 1 points."""
    v = np.linspace(0.0, 1.0, K.LUT_SIZE + 1)
    s = np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(v, 1 / 2.4) - 0.055)
    return np.clip(np.round(s * 255.0), 0, 255).astype(np.uint8)


_SRGB = srgb_lut()
BOUND_GROUPS = 32
"""Time groups per render for the conservative actor bounds that decide which lines an actor touches."""


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


class Renderer:
    """Renders one camera of a scene at arbitrary per-line times, with exact per-actor ground truth."""

    def __init__(self, scene: Scene, camera: Camera | int | str = 0, *, gain: float = 1.0) -> None:
        self.scene = scene
        self.camera = camera if isinstance(camera, Camera) else scene.camera(camera)
        if self.camera.width <= 0 or self.camera.height <= 0:
            raise ConfigError(f"camera size must be positive, got {self.camera.width}x{self.camera.height}")
        self.gain = float(gain)
        self._c = compile_scene(scene)
        self._cams = {False: compile_camera(self.camera, False), True: compile_camera(self.camera, True)}
        self._layers: dict[bool, _Layer] = {}
        self._parts: np.ndarray | None = None
        self.camera_moving = self.camera.ego.moving
        self.actor_ids = self._c.actor_ids
        self.actor_classes = self._c.actor_classes
        self.actor_speeds_mps = self._c.actor_speeds_mps

    # ------------------------------------------------------------------ public API
    @property
    def n_actors(self) -> int:
        """Number of actors (pedestrians, chart bars) in the scene."""
        return int(self._c.actors.shape[0])

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
        cam = self._cams[by_column]
        n_lines, n_along = self._shape(by_column)
        times_ns = self._check_times(times_ns, by_column)
        ut_ns, line_k = np.unique(times_ns, return_inverse=True)
        times_s = ut_ns.astype(np.float64) * 1e-9
        layer = self._layer(by_column, times_s[0])
        res = self._render(cam, times_s, line_k.astype(np.int64), n_lines, n_along, layer, linear, truth_only,
                           include=np.ones(self.n_actors, np.bool_), force_paint=False)
        return res

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
        n_lines, n_along = self._shape(by_column)
        times_ns = self._check_times(times_ns, by_column)
        subset = np.ones(n_lines, np.bool_)
        if lines is not None:
            lines = np.asarray(lines)
            if lines.dtype == np.bool_:
                if lines.shape != (n_lines,):
                    raise ConfigError(f"line mask must have {n_lines} entries, got shape {lines.shape}")
                subset = lines
            else:
                if lines.size and (lines.min() < 0 or lines.max() >= n_lines):
                    raise ConfigError(f"line indices must be in 0..{n_lines - 1}")
                subset = np.zeros(n_lines, np.bool_)
                subset[lines.astype(np.int64)] = True
        if out is None:
            out = np.empty((n_lines, n_along, 3), np.float32)
        elif out.shape != (n_lines, n_along, 3) or out.dtype != np.float32 or not out.flags.c_contiguous:
            raise ConfigError(f"out must be a C-contiguous float32 array of shape {(n_lines, n_along, 3)}, "
                              f"got {out.dtype} {out.shape}")
        if hits is not None and (hits.shape != (n_lines,) or hits.dtype != np.int64):
            raise ConfigError(f"hits must be an int64 array of {n_lines} counts, got {hits.dtype} {hits.shape}")
        # Only the asked-for lines' times are posed and bounded (a pass of an exposure needs few lines).
        sub_idx = np.flatnonzero(subset)
        ut_ns, sub_k = np.unique(times_ns[sub_idx] if sub_idx.size else times_ns[:1], return_inverse=True)
        line_k = np.zeros(n_lines, np.int64)
        line_k[sub_idx] = sub_k
        times_s = ut_ns.astype(np.float64) * 1e-9
        layer = self._layer(by_column, float(times_ns.min()) * 1e-9)
        return self._render(self._cams[by_column], times_s, line_k, n_lines, n_along, layer, True,
                            False, include=np.ones(self.n_actors, np.bool_), force_paint=False, subset=subset,
                            into=out, hits=hits)

    def reference_frame(self, t_ns: int, *, by_column: bool = False) -> RenderResult:
        """One full render with every line at ``t_ns`` and no shortcuts: every line painted over the bare
        background with every actor tested against it (no static-actor composite, no touched-line culling).
        """
        n_lines, n_along = self._shape(by_column)
        t_s = np.array([np.int64(t_ns).astype(np.float64) * 1e-9])
        layer = self._layer(by_column, t_s[0])
        return self._render(self._cams[by_column], t_s, np.zeros(n_lines, np.int64), n_lines, n_along, layer,
                            False, False, include=np.ones(self.n_actors, np.bool_), force_paint=True,
                            exhaustive=True)

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
            n_lines = self._shape(by_column)[0]
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

    # ------------------------------------------------------------------ internals
    def _shape(self, by_column: bool) -> tuple[int, int]:
        """(lines, pixels per line) of a render."""
        w, h = self.camera.width, self.camera.height
        return (w, h) if by_column else (h, w)

    def _check_times(self, times_ns: np.ndarray, by_column: bool) -> np.ndarray:
        n_lines = self._shape(by_column)[0]
        times_ns = np.asarray(times_ns, dtype=np.int64)
        if times_ns.shape != (n_lines,):
            raise ConfigError(f"need one time per line: {n_lines} lines, got times of shape {times_ns.shape}")
        return times_ns

    def _parts_buffer(self, n_slots: int) -> np.ndarray:
        """A parts table of at least ``n_slots`` slots, reused across renders.

        An RS frame needs thousands of slots (megabytes); a fresh array each frame would pay for its page
        faults every time. This is why a Renderer renders one frame at a time.
        """
        if self._parts is None or self._parts.shape[0] < n_slots:
            self._parts = np.empty((max(n_slots, 1024), K.MAX_PARTS, K.PART_COLS))
        return self._parts[:n_slots]

    def _touch(self, cam, times_s, rot_tab, pos_tab, k_line, moving, include, n_lines, n_along,
               obj_line_k, only=None, line_of=None) -> None:
        """Fill ``obj_line_k[o, line]`` with actor o's time slot on each line its bounds reach.

        ``only`` (line indices) limits the lines looked at; the others keep -1. With ``line_of`` the columns
        are samples, column e on line ``line_of[e]``.

        The bounds are conservative boxes over groups of consecutive times (one group per time when the
        camera moves, since each time then has its own pose); a static actor needs only its one time.
        """
        c = self._c
        n_obj, n_t = self.n_actors, times_s.shape[0]
        n_g = n_t if self.camera_moving else min(n_t, BOUND_GROUPS)
        group_of_k = (np.arange(n_t) * n_g) // n_t
        k_first = np.searchsorted(group_of_k, np.arange(n_g))
        k_last = np.searchsorted(group_of_k, np.arange(n_g), side="right") - 1
        need = np.zeros((n_obj, n_g), np.bool_)
        need[:, 0] = include
        need[moving, :] = True
        bounds = np.empty((n_obj, n_g, 4))
        K.actor_bounds_all(c.actors, c.world, cam, rot_tab, pos_tab, times_s[k_first], k_first,
                           times_s[k_last] - times_s[k_first], need, bounds)
        idx = np.arange(n_lines) if only is None else only
        centre = (idx if line_of is None else line_of[idx]) + 0.5
        objs = np.flatnonzero(include)
        # All included actors at once (one pass of an exposure is called often: Python loops add up).
        k = k_line[objs[:, None], idx[None, :]]
        b = bounds[objs[:, None], group_of_k[k]]
        touch = (b[..., 0] <= centre) & (centre <= b[..., 1]) & (b[..., 2] < n_along) & (b[..., 3] > 0)
        t_o, t_l = np.nonzero(touch)
        obj_line_k[objs[t_o], idx[t_l]] = k[t_o, t_l]

    def _shared_parts(self, cam, times_s, rot_tab, pos_tab, obj_line_k) -> tuple[np.ndarray, np.ndarray]:
        """Slot table and parts table of a render.

        Parts of an actor at an instant that several lines share (GS, bands, static actors) are computed once
        into a table; those only one line needs (RS) are computed on that line, in cache (``SLOT_LOCAL``).
        """
        c = self._c
        o_idx, l_idx = np.nonzero(obj_line_k >= 0)
        uses = np.zeros((self.n_actors, times_s.shape[0]), np.int64)
        np.add.at(uses, (o_idx, obj_line_k[o_idx, l_idx]), 1)
        slots = np.where(uses == 1, K.SLOT_LOCAL, K.SLOT_NONE)
        s_o, s_k = np.nonzero(uses > 1)
        slots[s_o, s_k] = np.arange(s_o.size)
        parts = self._parts_buffer(max(s_o.size, 1))
        if s_o.size:
            K.actor_parts_all(c.actors, c.world, c.building_lut, c.buildings, c.light, cam, rot_tab, pos_tab,
                              times_s, s_o, s_k, parts)
        return slots, parts

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
        n_lines, n_along = self._shape(by_column)
        times_ns = np.asarray(times_ns, np.int64)
        line_of = np.asarray(line_of, np.int64)
        n_ent = times_ns.shape[0]
        if line_of.shape != (n_ent,) or (n_ent and (line_of[0] < 0 or line_of[-1] >= n_lines
                                                    or (np.diff(line_of) < 0).any())):
            raise ConfigError(f"line_of must hold one non-decreasing line index in 0..{n_lines - 1} per sample")
        if out.shape != (n_lines, n_along, 3) or out.dtype != np.float32 or not out.flags.c_contiguous:
            raise ConfigError(f"out must be a C-contiguous float32 array of shape {(n_lines, n_along, 3)}, "
                              f"got {out.dtype} {out.shape}")
        if hits.shape != (n_lines,) or hits.dtype != np.int64:
            raise ConfigError(f"hits must be an int64 array of {n_lines} counts, got {hits.dtype} {hits.shape}")
        layer = self._layer(by_column, float(times_ns.min()) * 1e-9 if n_ent else 0.0)
        shared = None
        if not self.camera_moving:
            assert layer.comp_lin is not None
            shared = layer.comp_lin.view()
            shared.flags.writeable = False
        if n_ent == 0:
            return shared, 0
        c, cam, n_obj = self._c, self._cams[by_column], self.n_actors
        ut_ns, ent_k = np.unique(times_ns, return_inverse=True)
        ent_k = ent_k.astype(np.int64)
        times_s = ut_ns.astype(np.float64) * 1e-9
        n_t = times_s.shape[0]
        static = c.actors[:, B.A_STATIC] != 0.0 if n_obj else np.zeros(0, np.bool_)
        if self.camera_moving:
            static = np.zeros_like(static)
        k_line = np.where(static[:, None], 0, ent_k[None, :]) if n_obj else np.zeros((0, n_ent), np.int64)
        rot_tab, pos_tab = np.empty((n_t, 3, 3)), np.empty((n_t, 3))
        Wd.pose_table(cam, times_s, rot_tab, pos_tab)
        include = np.ones(n_obj, np.bool_)
        obj_line_k = np.full((n_obj, n_ent), -1, np.int64)
        self._touch(cam, times_s, rot_tab, pos_tab, k_line, ~static, include, n_ent, n_along, obj_line_k,
                    line_of=line_of)
        slots, parts = self._shared_parts(cam, times_s, rot_tab, pos_tab, obj_line_k)
        if self.camera_moving:
            ents = np.arange(n_ent)
            seed = np.empty((0, 0, 3), np.float32)
        else:
            ents = np.flatnonzero((obj_line_k[~static] >= 0).any(axis=0))
            seed = layer.comp_lin
        lines, first = np.unique(line_of[ents], return_index=True)
        e_start = np.append(first, ents.size).astype(np.int64)
        gt = LineTruth.empty(n_obj, n_lines, cam[Wd.C_TRANSPOSED] != 0.0)  # scratch for the kernel
        bg = layer.bg_lin if layer.bg_lin is not None else np.empty((0, 0, 3), np.float32)
        before = int(hits.sum())
        K.render_lines_kernel(c.world, c.building_lut, c.buildings, c.light, cam, rot_tab, pos_tab, c.actors, times_s,
                              ent_k, obj_line_k, slots, parts, include, lines.astype(np.int64), e_start, ents,
                              n_along, bg, np.empty((0, n_along, 3), np.uint8), out, self.gain, _SRGB, gt.left,
                              gt.right, gt.area, gt.visible, False, self.camera_moving, seed, hits,
                              np.zeros(0, np.bool_))
        return shared, int(hits.sum()) - before

    def _layer(self, by_column: bool, t0_s: float) -> _Layer:
        """Static layers for this orientation, built on first use (nothing to cache for a moving camera)."""
        layer = self._layers.get(by_column)
        if layer is not None:
            return layer
        cam = self._cams[by_column]
        n_lines, n_along = self._shape(by_column)
        c = self._c
        if self.camera_moving:
            layer = _Layer(None)
        else:
            bg = np.empty((n_lines, n_along, 3), np.float32)
            Wd.background_image(c.world, c.building_lut, c.buildings, c.light, cam, t0_s, bg)
            layer = _Layer(bg)
            static = c.actors[:, B.A_STATIC] != 0.0 if self.n_actors else np.zeros(0, np.bool_)
            res = self._render(cam, np.array([t0_s]), np.zeros(n_lines, np.int64), n_lines, n_along, layer,
                               True, False, include=static, force_paint=True)
            assert res.linear is not None
            layer.comp_lin = res.linear if not by_column else np.ascontiguousarray(res.linear.transpose(1, 0, 2))
            img = res.image if not by_column else res.image.transpose(1, 0, 2)
            layer.comp_u8 = np.ascontiguousarray(img)
            t = res.truth
            layer.comp_gt = np.stack([t.left, t.right, t.area.astype(np.float64), t.visible.astype(np.float64)])
        self._layers[by_column] = layer
        return layer

    def _render(self, cam, times_s, line_k, n_lines, n_along, layer: _Layer, linear, truth_only, include,
                force_paint, exhaustive=False, subset=None, into=None, hits=None) -> RenderResult:
        """Paint a frame; with ``into`` (render_linear), only the ``subset`` lines, linear only, into it."""
        c = self._c
        n_obj, n_t = self.n_actors, times_s.shape[0]
        static = c.actors[:, B.A_STATIC] != 0.0 if n_obj else np.zeros(0, np.bool_)
        if self.camera_moving:
            static = np.zeros_like(static)
        # Actor time slot per line: a moving actor uses the line's own time, a static one the first time.
        k_line = np.where(static[:, None], 0, line_k[None, :]) if n_obj else np.zeros((0, n_lines), np.int64)
        rot_tab = np.empty((n_t, 3, 3))
        pos_tab = np.empty((n_t, 3))
        Wd.pose_table(cam, times_s, rot_tab, pos_tab)
        obj_line_k = np.full((n_obj, n_lines), -1, np.int64)
        if exhaustive:  # the oracle: every included actor is tried on every line
            obj_line_k[include] = k_line[include]
        else:
            # Lines not asked for are not looked at: no parts or truth work for them.
            self._touch(cam, times_s, rot_tab, pos_tab, k_line, include & ~static, include, n_lines, n_along,
                        obj_line_k, None if subset is None else np.flatnonzero(subset))
        slots, parts = self._shared_parts(cam, times_s, rot_tab, pos_tab, obj_line_k)
        gt = LineTruth.empty(n_obj, n_lines, cam[Wd.C_TRANSPOSED] != 0.0)
        full_lines = force_paint or self.camera_moving
        seed = np.empty((0, 0, 3), np.float32)
        if into is not None:
            # Linear-only subset render: paint the asked-for lines a moving actor touches (all of them for a
            # moving camera) into the buffer, each seeded from the composite in the kernel; no 8-bit image.
            out_u8, out_lin = np.empty((0, n_along, 3), np.uint8), into
            if full_lines:
                lines = np.flatnonzero(subset)
            else:
                assert layer.comp_gt is not None and layer.comp_lin is not None
                moving = include & ~static
                lines = np.flatnonzero((obj_line_k[moving] >= 0).any(axis=0) & subset)
                seed = layer.comp_lin
                gt.left[:], gt.right[:] = layer.comp_gt[0], layer.comp_gt[1]
                gt.area[:], gt.visible[:] = layer.comp_gt[2], layer.comp_gt[3]
        elif full_lines:
            lines = np.arange(n_lines)
            out_u8 = np.empty((n_lines, n_along, 3), np.uint8)
            out_lin = np.empty((n_lines, n_along, 3) if linear else (0, 0, 3), np.float32)
        else:
            # Start from the cached composite (one memcpy) and repaint only lines a moving actor touches.
            assert layer.comp_u8 is not None and layer.comp_gt is not None and layer.comp_lin is not None
            moving = include & ~static
            lines = np.flatnonzero((obj_line_k[moving] >= 0).any(axis=0))
            out_u8 = np.empty((0, n_along, 3), np.uint8) if truth_only else layer.comp_u8.copy()
            out_lin = layer.comp_lin.copy() if linear and not truth_only else np.empty((0, 0, 3), np.float32)
            gt.left[:], gt.right[:] = layer.comp_gt[0], layer.comp_gt[1]
            gt.area[:], gt.visible[:] = layer.comp_gt[2], layer.comp_gt[3]
        bg = layer.bg_lin if layer.bg_lin is not None else np.empty((0, 0, 3), np.float32)
        painted = np.zeros(n_lines if into is not None else 0, np.bool_)
        K.render_lines_kernel(c.world, c.building_lut, c.buildings, c.light, cam, rot_tab, pos_tab, c.actors, times_s,
                              line_k, obj_line_k, slots, parts, include, lines, np.arange(lines.size + 1), lines,
                              n_along, bg, out_u8, out_lin,
                              self.gain, _SRGB, gt.left, gt.right, gt.area, gt.visible, truth_only, full_lines, seed,
                              hits if hits is not None else np.empty(0, np.int64), painted)
        if into is not None:
            shared = None
            if not full_lines:
                shared = seed.view()
                shared.flags.writeable = False  # the renderer's cache: readers must not write through it
            frame = LinearFrame(shared, into, painted, bool(cam[Wd.C_TRANSPOSED] != 0.0))
            return RenderResult(np.empty((0, 0, 3), np.uint8), None, gt, int(painted.sum()), frame)
        if truth_only:
            return RenderResult(np.empty((0, 0, 3), np.uint8), None, gt, int(lines.size))
        image = out_u8.transpose(1, 0, 2) if cam[Wd.C_TRANSPOSED] != 0.0 else out_u8
        lin = None
        if linear:
            lin = out_lin.transpose(1, 0, 2) if cam[Wd.C_TRANSPOSED] != 0.0 else out_lin
        return RenderResult(np.ascontiguousarray(image), lin, gt, int(lines.size))
