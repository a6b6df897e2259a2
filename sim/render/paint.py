"""Render passes of the per-line renderer: poses, touched lines, shared actor parts, and the one kernel call.

``renderer.Renderer`` decides what a render needs (which lines, over which layer, into which
buffers); ``Painter.prepare`` does the work every render shares (camera poses at the distinct times, which
actor touches which line at which time, the parts several lines share) into a ``Pass``, and
``Painter.paint`` is the only caller of the line kernel, so every render goes through the same code.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numba
import numpy as np

from ..scene import Camera, Scene
from . import actors as A
from . import body as B
from . import egoblur as E
from . import lines as K
from . import world as Wd
from .result import LineTruth
from .tables import compile_camera, compile_scene

BOUND_GROUPS = 32
"""Time groups per render for the conservative actor bounds that decide which lines an actor touches."""

PARALLEL_MIN_PIXELS = 1 << 18
"""Work (pixels shaded) below which a kernel runs on the calling thread alone: waking the numba threads costs
tens of microseconds on a quiet machine and milliseconds on a busy one (a parked thread waits for a core)."""
TOUCH_WORK = 128
"""Pixels' shading one actor costs on one line over the cached composite (measured at 1080p: ~4 us a touch
against ~30 ns a background pixel), for ``PARALLEL_MIN_PIXELS``."""
TRUTH_TOUCH_WORK = 16
"""The same for a truth-only touch (parts, spans and covered pixels, no shading; ~0.5 us at 1080p): a frame's
ground truth at another instant stays on the calling thread unless hundreds of actors make it worth the threads."""
PARALLEL_MIN_ITEMS = 2048
"""Actor bounds or parts below which they are computed on the calling thread alone (same reason)."""

PATH_READ_WORK = 8
"""Pixels' shading one pixel's background path blur costs (its samples' bilinear reads), for
``PARALLEL_MIN_PIXELS``."""
PATH_VELOCITY_STEP_NS = 100_000
"""Time step of the image velocity behind the path blur's rolling-shutter correction: short beside a 60 Hz
vibration's period, long beside float64 pose noise."""

_EMPTY_LIN = np.empty((0, 0, 3), np.float32)

_PARALLEL_LOCK = threading.Lock()
"""Held around every call of a parallel kernel. The kernels release the GIL (``nogil``), so two threads may
render at once; numba's threading layers differ in whether concurrent parallel launches are safe (workqueue's
are not), and two launches would only share the same cores anyway. Serial kernels run concurrently."""


@dataclass
class Pass:
    """What one kernel call shares: the distinct times, their camera poses, and each actor's time slot per entry.

    An entry is a line at one time: one per line for a frame, one per (line, sample) for exposure integration.
    ``obj_k[o, e]`` is actor o's time slot on entry e (-1 when its bounds do not reach that line then);
    ``slots``/``parts`` are the shared parts table (``K.SLOT_LOCAL``: computed on the one line needing it).
    """

    cam: np.ndarray
    times_s: np.ndarray
    entry_k: np.ndarray
    rot: np.ndarray
    pos: np.ndarray
    obj_k: np.ndarray
    slots: np.ndarray
    parts: np.ndarray
    moving: np.ndarray  # (actors,) bool: moves in render space (every actor when the camera moves)
    n_along: int  # pixels per line

    def touched(self, include: np.ndarray) -> np.ndarray:
        """Entries some included moving actor's bounds reach (bool per entry)."""
        return (self.obj_k[include & self.moving] >= 0).any(axis=0)


class Painter:
    """The kernel tables of one scene camera (both orientations) and the render passes over them."""

    def __init__(self, scene: Scene, camera: Camera, gain: float, lut: np.ndarray, threads: int | None = None) -> None:
        self.gain, self.lut = gain, lut  # the 8-bit output: radiance scale and encoding curve
        self.threads = threads  # numba threads for large kernels (None: numba's setting; 1: the caller's only)
        self.tables = compile_scene(scene)
        self.cams = {False: compile_camera(camera, False), True: compile_camera(camera, True)}
        self.camera_moving = camera.ego.moving
        self._size = (camera.width, camera.height)
        actors = self.tables.actors
        self.n_actors = int(actors.shape[0])
        self.actor_static = actors[:, B.A_STATIC] != 0.0 if self.n_actors else np.zeros(0, np.bool_)
        # Fixed in render space: a static actor seen from a static camera.
        self.fixed = self.actor_static & (not self.camera_moving)
        self._parts: np.ndarray | None = None
        self._blur: tuple[np.ndarray, np.ndarray] | None = None

    def shape(self, by_column: bool) -> tuple[int, int]:
        """(lines, pixels per line) of a render: (height, width), or (width, height) by column."""
        w, h = self._size
        return (w, h) if by_column else (h, w)

    def poses(self, by_column: bool, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Camera rotation ``(n, 3, 3)`` and position ``(n, 3)`` at each time (seconds)."""
        n = times_s.shape[0]
        rot, pos = np.empty((n, 3, 3)), np.empty((n, 3))
        Wd.pose_table(self.cams[by_column], times_s, rot, pos)
        return rot, pos

    def background(self, by_column: bool, t_s: float, out: np.ndarray) -> None:
        """The static world (no actors) seen at time ``t_s``, linear RGB, into ``out`` (render orientation)."""
        t = self.tables
        with _PARALLEL_LOCK:
            Wd.background_image(t.world, t.building_lut, t.buildings, t.light, self.cams[by_column], t_s, out)

    def bounds(self, cam: np.ndarray, rot: np.ndarray, pos: np.ndarray, t_first: np.ndarray, k_first: np.ndarray,
               span_s: np.ndarray, need: np.ndarray) -> np.ndarray:
        """Render-space box (ymin, ymax, xmin, xmax) of actor o over group g, from ``t_first[g]`` lasting
        ``span_s[g]`` at pose ``k_first[g]``, where ``need[o, g]`` (other entries are not written)."""
        out = np.empty((*need.shape, 4))
        t = self.tables
        self._run(A.actor_bounds_all, A.actor_bounds_par, int(need.sum()), PARALLEL_MIN_ITEMS,
                  t.actors, t.world, cam, rot, pos, t_first, k_first, span_s, need, out)
        return out

    def speeds(self, by_column: bool, times_s: np.ndarray, need: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Fastest render-space displacement rate (px/s) of each actor's parts over ``times_s``, of the actors
        ``need`` (bool per actor; all when None) selects (0 for the others), and per part its own rate and line
        range (``A.actor_speeds``'s ``part_rate``, ``part_y``)."""
        rot, pos = self.poses(by_column, times_s)
        t = self.tables
        out = np.zeros(self.n_actors)
        part_rate = np.zeros((self.n_actors, A.MAX_PARTS))
        part_y = np.empty((self.n_actors, A.MAX_PARTS, 2))
        part_y[..., 0], part_y[..., 1] = np.inf, -np.inf
        need = np.ones(self.n_actors, np.bool_) if need is None else need
        self._run(A.actor_speeds, A.actor_speeds_par, int(need.sum()) * times_s.shape[0], PARALLEL_MIN_ITEMS,
                  t.actors, t.world, t.building_lut, t.buildings, t.light, self.cams[by_column], rot, pos, times_s,
                  need, out, part_rate, part_y)
        return out, part_rate, part_y

    def parts(self, by_column: bool, times_s: np.ndarray) -> np.ndarray:
        """Render-space parts ``(actors, times, A.MAX_PARTS, A.PART_COLS)`` of every actor at every time."""
        rot, pos = self.poses(by_column, times_s)
        n_t = times_s.shape[0]
        s_o, s_k = np.repeat(np.arange(self.n_actors), n_t), np.tile(np.arange(n_t), self.n_actors)
        out = np.empty((self.n_actors * n_t, A.MAX_PARTS, A.PART_COLS))
        t = self.tables
        self._run(A.actor_parts_all, A.actor_parts_par, s_o.size, PARALLEL_MIN_ITEMS, t.actors, t.world,
                  t.building_lut, t.buildings, t.light, self.cams[by_column], rot, pos, times_s, s_o, s_k, out)
        return out.reshape(self.n_actors, n_t, A.MAX_PARTS, A.PART_COLS)

    def prepare(self, by_column: bool, times_s: np.ndarray, entry_k: np.ndarray, include: np.ndarray, n_along: int,
                *, exhaustive: bool = False, only: np.ndarray | None = None,
                line_of: np.ndarray | None = None) -> Pass:
        """The shared work of a render of entries at ``times_s[entry_k]``, for the ``include``d actors.

        ``exhaustive`` (the oracle) tries every included actor on every entry instead of bounding them;
        ``only`` (entry indices) limits the entries looked at; ``line_of`` maps entries to lines (default:
        entry e is line e).
        """
        cam = self.cams[by_column]
        n_ent = entry_k.shape[0]
        fixed = self.fixed
        # Actor time slot per entry: a moving actor uses the entry's own time, a fixed one the first time.
        if self.n_actors:
            k_line = np.where(fixed[:, None], 0, entry_k[None, :])
        else:
            k_line = np.zeros((0, n_ent), np.int64)
        rot, pos = self.poses(by_column, times_s)
        obj_k = np.full((self.n_actors, n_ent), -1, np.int64)
        if exhaustive:
            obj_k[include] = k_line[include]
        else:
            self._touch(cam, times_s, rot, pos, k_line, include & ~fixed, include, n_along, obj_k, only, line_of)
        slots, parts = self._shared_parts(cam, times_s, rot, pos, obj_k)
        return Pass(cam, times_s, entry_k, rot, pos, obj_k, slots, parts, ~fixed, n_along)

    def paint(self, p: Pass, include: np.ndarray, lines: np.ndarray, gt: LineTruth, *, bg: np.ndarray | None,
              out_u8: np.ndarray | None = None, out_lin: np.ndarray | None = None, full_lines: bool,
              gt_only: bool = False, seed: np.ndarray | None = None, hits: np.ndarray | None = None,
              line_hit: np.ndarray | None = None, e_start: np.ndarray | None = None,
              ents: np.ndarray | None = None) -> None:
        """Run the line kernel on ``lines`` (see ``K.render_lines_kernel``; None stands for an empty array).

        Without ``e_start``/``ents`` each line is painted once, as its own entry.
        """
        t, n_along = self.tables, p.n_along
        if e_start is None:
            e_start, ents = np.arange(lines.size + 1), lines
        # Whole lines shade every pixel; over a composite only the actors' spans, each touch of an actor and
        # a line costing about TOUCH_WORK pixels' shading (its parts on that line, its spans, their pixels).
        if full_lines and not gt_only:
            work = ents.size * n_along
        else:
            touches = int((p.obj_k >= 0).sum(axis=0)[ents].sum())
            work = (TRUTH_TOUCH_WORK if gt_only else TOUCH_WORK) * touches
        self._run(
            K.render_lines_kernel, K.render_lines_par, work, PARALLEL_MIN_PIXELS,
            t.world, t.building_lut, t.buildings, t.light, p.cam, p.rot, p.pos, t.actors, p.times_s, p.entry_k,
            p.obj_k, p.slots, p.parts, include, lines, e_start, ents, n_along,
            _EMPTY_LIN if bg is None else bg,
            np.empty((0, n_along, 3), np.uint8) if out_u8 is None else out_u8,
            _EMPTY_LIN if out_lin is None else out_lin,
            self.gain, self.lut, gt.left, gt.right, gt.area, gt.visible, gt_only,
            full_lines, _EMPTY_LIN if seed is None else seed,
            np.empty(0, np.int64) if hits is None else hits,
            np.zeros(0, np.bool_) if line_hit is None else line_hit)

    def whole(self, p: Pass, include: np.ndarray, bg: np.ndarray | None, by_column: bool, linear: bool
              ) -> tuple[np.ndarray, np.ndarray | None, LineTruth]:
        """Every line painted whole, over ``bg`` (or the background at each line's pose, for a moving camera):
        8-bit, linear when asked, and truth, in render orientation."""
        n_lines, n_along = self.shape(by_column)
        u8 = np.empty((n_lines, n_along, 3), np.uint8)
        lin = np.empty((n_lines, n_along, 3), np.float32) if linear else None
        gt = LineTruth.empty(self.n_actors, n_lines, by_column)
        self.paint(p, include, np.arange(n_lines), gt, bg=bg, out_u8=u8, out_lin=lin, full_lines=True)
        return u8, lin, gt

    def path_blur(self, by_column: bool, starts_ns: np.ndarray, exposure_ns: int, n_path: np.ndarray,
                  n_actor: np.ndarray, margin: int, acc: np.ndarray, hits: np.ndarray) -> None:
        """A moving camera's exposure-integrated lines into ``acc``: each line's background integrated along its
        pixels' image paths (``n_path[l]`` midpoint samples of the window ``starts_ns[l] + [0, exposure_ns]``;
        ``egoblur``) plus, on lines with ``hits``, the actors' accumulated samples in ``acc`` over
        ``n_actor[l]`` (see ``K._add_over``). ``margin``: render pixels of background beyond each image edge."""
        t, cam = self.tables, self.cams[by_column]
        n_lines, n_along = self.shape(by_column)
        mid_ns = starts_ns + exposure_ns // 2
        # The frame's lines at their mid-exposure poses, and its margins at the end lines' spacing beyond them.
        step = (int(mid_ns[-1]) - int(mid_ns[0])) // max(n_lines - 1, 1)
        ext = np.arange(-margin, n_lines + margin)
        ext_ns = mid_ns[np.clip(ext, 0, n_lines - 1)] + (ext - np.clip(ext, 0, n_lines - 1)) * step
        rot_e, pos_e = self.poses(by_column, ext_ns.astype(np.float64) * 1e-9)
        bg, surface = self._blur_buffers((n_lines + 2 * margin, n_along + 2 * margin))
        self._run(E.background_frame, E.background_frame_par, bg.shape[0] * bg.shape[1], PARALLEL_MIN_PIXELS,
                  t.world, t.building_lut, t.buildings, t.light, cam, rot_e, pos_e, margin, bg, surface)
        n_s = int(n_path.max())
        k = np.minimum(np.arange(n_s)[None, :], n_path[:, None] - 1)
        times_ns = np.empty((n_lines, n_s + 1), np.int64)
        times_ns[:, :n_s] = starts_ns[:, None] + ((2 * k + 1) * exposure_ns) // (2 * n_path[:, None])
        times_ns[:, n_s] = mid_ns - PATH_VELOCITY_STEP_NS
        rot_t, pos_t = self.poses(by_column, times_ns.ravel().astype(np.float64) * 1e-9)
        homs = E.plane_homographies(rot_e[margin:margin + n_lines], pos_e[margin:margin + n_lines],
                                    rot_t.reshape(n_lines, n_s + 1, 3, 3), pos_t.reshape(n_lines, n_s + 1, 3),
                                    E.facade_x(t.world))
        lt_s = (np.gradient(mid_ns.astype(np.float64)) * 1e-9 if n_lines > 1 else np.zeros(n_lines))
        self._run(E.path_blur, E.path_blur_par, n_lines * n_along * PATH_READ_WORK, PARALLEL_MIN_PIXELS,
                  bg, surface, margin, cam, homs, n_path.astype(np.int64), PATH_VELOCITY_STEP_NS * 1e-9, lt_s, acc,
                  hits, n_actor.astype(np.int64), acc)

    # ------------------------------------------------------------------ internals
    def _blur_buffers(self, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        """The background frame and surface buffers of ``path_blur`` (reused: 30 MB at 1080p)."""
        if self._blur is None or self._blur[0].shape[:2] != shape:
            self._blur = (np.empty((*shape, 3), np.float32), np.empty(shape, np.int8))
        return self._blur

    def _run(self, serial, parallel, work: int, threshold: int, *args) -> None:
        """Call ``serial(*args)``, or ``parallel(*args)`` (under the parallel-launch lock) for enough work."""
        if not self._parallel(work, threshold):
            serial(*args)
            return
        with _PARALLEL_LOCK:
            parallel(*args)

    def _parallel(self, work: int, threshold: int) -> bool:
        """Whether a kernel of this much work runs over the numba threads (set to ``threads`` when given)."""
        if self.threads == 1 or work < threshold:
            return False
        if self.threads is not None:
            numba.set_num_threads(min(self.threads, numba.config.NUMBA_NUM_THREADS))
        return True

    def _touch(self, cam, times_s, rot, pos, k_line, moving, include, n_along, obj_k, only, line_of) -> None:
        """Fill ``obj_k[o, e]`` with actor o's time slot on each entry its bounds reach.

        The bounds are conservative boxes over groups of consecutive times (one group per time when the
        camera moves, since each time then has its own pose); an actor fixed in render space needs only its
        one time.
        """
        n_obj, n_t = self.n_actors, times_s.shape[0]
        n_g = n_t if self.camera_moving else min(n_t, BOUND_GROUPS)
        group_of_k = (np.arange(n_t) * n_g) // n_t
        k_first = np.searchsorted(group_of_k, np.arange(n_g))
        k_last = np.searchsorted(group_of_k, np.arange(n_g), side="right") - 1
        need = np.zeros((n_obj, n_g), np.bool_)
        need[:, 0] = include
        need[moving, :] = True
        bounds = self.bounds(cam, rot, pos, times_s[k_first], k_first, times_s[k_last] - times_s[k_first], need)
        idx = np.arange(obj_k.shape[1]) if only is None else only
        centre = (idx if line_of is None else line_of[idx]) + 0.5
        K.touch_entries(bounds, group_of_k, k_line, np.flatnonzero(include), idx.astype(np.int64),
                        centre.astype(np.float64), n_along, obj_k)

    def _shared_parts(self, cam, times_s, rot, pos, obj_k) -> tuple[np.ndarray, np.ndarray]:
        """Slot table and parts table of a render.

        Parts of an actor at an instant that several entries share (GS, bands, static actors) are computed
        once into a table; those only one entry needs (RS) are computed on that line, in cache
        (``K.SLOT_LOCAL``).
        """
        t = self.tables
        slots = np.empty((self.n_actors, times_s.shape[0]), np.int64)
        s_o, s_k = K.part_slots(obj_k, times_s.shape[0], slots)
        parts = self._parts_buffer(max(s_o.size, 1))
        if s_o.size:
            self._run(A.actor_parts_all, A.actor_parts_par, s_o.size, PARALLEL_MIN_ITEMS, t.actors, t.world,
                      t.building_lut, t.buildings, t.light, cam, rot, pos, times_s, s_o, s_k, parts)
        return slots, parts

    def _parts_buffer(self, n_slots: int) -> np.ndarray:
        """A parts table of at least ``n_slots`` slots, reused across renders.

        An RS frame needs thousands of slots (megabytes); a fresh array each frame would pay for its page
        faults every time. This is why a Renderer renders one frame at a time.
        """
        if self._parts is None or self._parts.shape[0] < n_slots:
            self._parts = np.empty((max(n_slots, 1024), A.MAX_PARTS, A.PART_COLS))
        return self._parts[:n_slots]
