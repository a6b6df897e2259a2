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

import numpy as np
from rollcam.common.errors import ConfigError

from ..frame import ObjectTruth
from ..scene import Camera, Scene
from . import lines as K
from .composite import Compositor
from .paint import Painter
from .result import LinearFrame, LineTruth, RenderResult, object_truths

__all__ = ["LineTruth", "LinearFrame", "RenderResult", "Renderer", "encode_linear", "srgb_lut"]


def srgb_lut() -> np.ndarray:
    """8-bit sRGB encoding of linear values 0..1 sampled at LUT_SIZE + 1 points."""
    v = np.linspace(0.0, 1.0, K.LUT_SIZE + 1)
    s = np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(v, 1 / 2.4) - 0.055)
    return np.clip(np.round(s * 255.0), 0, 255).astype(np.uint8)


SRGB = srgb_lut()
"""The renderer's linear -> 8-bit sRGB table (``srgb_lut``), shared by every renderer of the package."""


def encode_linear(linear: np.ndarray, gain: float) -> np.ndarray:
    """The 8-bit BGR image ``(H, W, 3)`` of a linear RGB one, encoded as a renderer of ``gain`` (``Renderer.gain``)
    encodes its lines (scale, clip, sRGB curve): for images changed after the render (the lens,
    ``rollcam.sim.optics``)."""
    lin = np.ascontiguousarray(linear, np.float32)
    if lin.ndim != 3 or lin.shape[2] != 3:
        raise ConfigError(f"a linear image is (H, W, 3), got shape {lin.shape}")
    out = np.empty(lin.shape, np.uint8)
    K.encode_line(lin.reshape(-1, 3), float(gain), SRGB, out.reshape(-1, 3))
    return out


LIT_RENDERER: list[type[Renderer]] = []
"""The renderer ``Renderer(scene)`` is for a scene with modulated lights: ``FlickerRenderer``, registered by its
module (``register_lit_renderer``), which the package imports with this one, so this module needs no import of
it."""


def register_lit_renderer(cls: type[Renderer]) -> None:
    """Make ``Renderer(scene)`` of a scene with modulated lights a ``cls``."""
    LIT_RENDERER[:] = [cls]


class Renderer:
    """Renders one camera of a scene at arbitrary per-line times, with exact per-actor ground truth.

    Four operations, one kernel (``paint.Painter``), over the static layers ``composite.Compositor`` caches:
    a frame of lines (8-bit, optionally linear), its ground truth only, linear radiance of chosen lines into a
    buffer (or accumulated, for exposure integration), and the brute-force reference. The sensor path's
    planning reads the scene through ``poses``, ``actor_bounds`` and ``actor_image_speeds``.
    ``threads`` caps the numba threads its large kernels use (None: numba's setting; 1: the calling thread
    only); small ones always run on the calling thread. A scene with modulated lights gets a ``FlickerRenderer``.
    """

    def __new__(cls, scene: Scene | None = None, *args, **kwargs) -> Renderer:  # (no scene: copy/pickle)
        lit = cls is Renderer and bool(getattr(scene, "lights", ()))
        return super().__new__(LIT_RENDERER[0] if lit else cls)  # modulated lights: a sum of renders

    def __init__(self, scene: Scene, camera: Camera | int | str = 0, *, gain: float = 1.0,
                 threads: int | None = None, light_window_ns: int = 0) -> None:
        self.scene, self.light_window_ns = scene, int(light_window_ns)  # a line's light window (modulated lights)
        self.camera = camera if isinstance(camera, Camera) else scene.camera(camera)
        if self.camera.width <= 0 or self.camera.height <= 0:
            raise ConfigError(f"camera size must be positive, got {self.camera.width}x{self.camera.height}")
        if threads is not None and (not isinstance(threads, int) or threads < 1):
            raise ConfigError(f"threads must be an integer >= 1 or None, got {threads!r}")
        self._painter = Painter(scene, self.camera, float(gain), SRGB, threads)
        self._composite = Compositor(self._painter)
        self.camera_moving = self.camera.ego.moving
        t = self._painter.tables  # actor_labelled: False for props (scenery, no truth record)
        self.actor_ids, self.actor_classes, self.actor_speeds_mps = t.actor_ids, t.actor_classes, t.actor_speeds_mps
        self.actor_labelled = t.actor_labelled
        self._all = np.ones(self.n_actors, np.bool_)

    # ------------------------------------------------------------------ the scene as the renderer sees it
    @property
    def gain(self) -> float:
        """Scale from linear radiance to the 8-bit image's encoding input."""
        return self._painter.gain

    @property
    def n_actors(self) -> int:
        """Number of actors (pedestrians, chart bars, prop rows) in the scene."""
        return self._painter.n_actors

    @property
    def moving_actors(self) -> np.ndarray:
        """Indices of the actors that move in the scene (whatever the camera does)."""
        return np.flatnonzero(~self._painter.actor_static)

    def render_shape(self, by_column: bool = False) -> tuple[int, int]:
        """(lines, pixels per line) of a render: (height, width), or (width, height) by column."""
        return self._painter.shape(by_column)

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

    def actor_image_speeds(self, times_s: np.ndarray, *, by_column: bool = False,
                           actors: np.ndarray | None = None) -> np.ndarray:
        """Per actor, the fastest render-space displacement rate (px/s) of its parts between consecutive times.

        Parts wholly off the image by more than half its size are ignored (see ``actors.actor_speeds``);
        a chart bar's rate is its speed. ``actors`` (bool mask or indices) limits the work to those actors;
        the others read 0.
        """
        return self.actor_part_motion(times_s, by_column=by_column, actors=actors)[0]

    def actor_part_motion(self, times_s: np.ndarray, *, by_column: bool = False, actors: np.ndarray | None = None
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``actor_image_speeds`` and, per actor and part (``(actors, MAX_PARTS)``), the part's own fastest rate
        (px/s; -1 where it is not measured: a shadow, a chart bar, a part that appears or changes kind between two
        times, whose motion is then the actor's) and ``(actors, MAX_PARTS, 2)`` the lowest and highest render
        line it reaches at any of the times ((inf, -inf) if it never shows). The exposure plan's per-line speed."""
        need = None
        if actors is not None:
            actors = np.asarray(actors)
            if actors.dtype == np.bool_ and actors.shape != (self.n_actors,):
                raise ConfigError(f"actor mask must have {self.n_actors} entries, got shape {actors.shape}")
            if actors.dtype != np.bool_ and actors.size and (actors.min() < 0 or actors.max() >= self.n_actors):
                raise ConfigError(f"actor indices must be in 0..{self.n_actors - 1}, got {actors!r}")
            need = actors if actors.dtype == np.bool_ else np.isin(np.arange(self.n_actors), actors)
        return self._painter.speeds(by_column, np.asarray(times_s, np.float64), need)

    def actor_parts(self, times_s: np.ndarray, *, by_column: bool = False) -> np.ndarray:
        """The render-space primitives the kernels draw: ``(actors, times, MAX_PARTS, PART_COLS)`` float64.

        Row layout in ``actors`` (``Q_KIND`` capsule, quad or none; geometry from ``Q_GEO``;
        line range ``Q_YMIN``..``Q_YMAX``). For checks and studies; a render computes only the parts it needs.
        """
        return self._painter.parts(by_column, np.asarray(times_s, np.float64))

    # ------------------------------------------------------------------ frames
    def render_lines(self, times_ns: np.ndarray, *, by_column: bool = False, linear: bool = False,
                     truth_only: bool = False) -> RenderResult:
        """Render every image line at its own time (``times_ns``: int64, one per row or per column).

        Returns the 8-bit BGR image in image orientation, the linear RGB float32 image when ``linear``,
        and the per-line ground truth. ``truth_only`` skips pixels (for boxes at another instant).
        """
        n_lines, n_along = self.render_shape(by_column)
        times_ns = check_times(times_ns, n_lines)
        ut_ns, line_k = np.unique(times_ns, return_inverse=True)
        times_s = ut_ns.astype(np.float64) * 1e-9
        layer = self._composite.layers.get(by_column, times_s[0])
        p = self._painter.prepare(by_column, times_s, line_k.astype(np.int64), self._all, n_along)
        if truth_only:
            return self._composite.truth(p, layer, by_column)
        return self._composite.frame(p, layer, by_column, linear)

    def render_linear(self, times_ns: np.ndarray, *, by_column: bool = False, lines: np.ndarray | None = None,
                      out: np.ndarray | None = None, hits: np.ndarray | None = None) -> RenderResult:
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
        times_ns = check_times(times_ns, n_lines)
        subset = line_mask(lines, n_lines)
        if out is None:
            out = np.empty((n_lines, n_along, 3), np.float32)
        check_buffers(out, hits, (n_lines, n_along))
        # Only the asked-for lines' times are posed and bounded (a pass of an exposure needs few lines).
        sub_idx = np.flatnonzero(subset)
        ut_ns, sub_k = np.unique(times_ns[sub_idx] if sub_idx.size else times_ns[:1], return_inverse=True)
        line_k = np.zeros(n_lines, np.int64)
        line_k[sub_idx] = sub_k
        times_s = ut_ns.astype(np.float64) * 1e-9
        layer = self._composite.layers.get(by_column, float(times_ns.min()) * 1e-9)
        p = self._painter.prepare(by_column, times_s, line_k, self._all, n_along, only=sub_idx)
        return self._composite.linear_into(p, layer, by_column, subset, out, hits)

    def accumulate_samples(self, times_ns: np.ndarray, line_of: np.ndarray, out: np.ndarray, hits: np.ndarray,
                           *, by_column: bool = False, actors_only: bool = False) -> tuple[np.ndarray | None, int]:
        """Render many (line, time) samples in one go and accumulate them, as ``render_linear(hits=...)`` does.

        Sample e is line ``line_of[e]`` (non-decreasing: a line's samples together) at ``times_ns[e]``. Each
        painted sample is added to ``out`` (render orientation) as its difference from the static composite
        (or whole, for a moving camera) and counted in ``hits``; samples no actor pixel lands on are the
        composite and skipped. One call instead of one per sample index saves the per-call set-up that
        dominates many-pass exposures. Returns the shared composite (None for a moving camera) and the
        number of samples painted. Ground truth is not produced.

        ``actors_only`` (a moving camera; no effect on a static one): only samples an actor touches are painted,
        and each adds what its actors change over the background at its own pose, under their spans; the
        background itself is ``path_blur``'s.
        """
        n_lines, n_along = self.render_shape(by_column)
        times_ns = np.asarray(times_ns, np.int64)
        line_of = _check_line_of(line_of, times_ns.shape[0], n_lines)
        check_buffers(out, hits, (n_lines, n_along), need_hits=True)
        n_ent = times_ns.shape[0]
        layer = self._composite.layers.get(by_column, float(times_ns.min()) * 1e-9 if n_ent else 0.0)
        if n_ent == 0:
            return self._composite.shared(layer), 0
        ut_ns, ent_k = np.unique(times_ns, return_inverse=True)
        p = self._painter.prepare(by_column, ut_ns.astype(np.float64) * 1e-9, ent_k.astype(np.int64), self._all,
                                  n_along, line_of=line_of)
        return self._composite.accumulate(p, layer, line_of, out, hits, by_column, actors_only)

    def path_blur(self, starts_ns: np.ndarray, exposure_ns: int, n_path: np.ndarray, n_actor: np.ndarray,
                  out: np.ndarray, hits: np.ndarray, *, by_column: bool = False, margin: int = 0) -> None:
        """A moving camera's exposure integral into ``out`` (render orientation): each line's static background
        integrated along its pixels' image paths (``n_path[l]`` midpoint samples of the window
        ``starts_ns[l] + [0, exposure_ns]``, each a bilinear read of one render of the background, mapped
        through the plane the pixel's ray hits: ``egoblur``), plus on lines with ``hits`` the
        actors' samples that ``accumulate_samples(actors_only=True)`` left in ``out``, over ``n_actor[l]``.
        ``margin`` render pixels of background are rendered beyond each image edge for reads that leave it."""
        if not self.camera_moving:
            raise ConfigError("path_blur integrates a moving camera's background; a static one's is its composite")
        n_lines, n_along = self.render_shape(by_column)
        starts_ns = check_times(starts_ns, n_lines)
        check_buffers(out, hits, (n_lines, n_along), need_hits=True)
        n_path, n_actor = np.asarray(n_path, np.int64), np.asarray(n_actor, np.int64)
        if n_path.shape != (n_lines,) or n_actor.shape != (n_lines,) or (n_path < 1).any() or (n_actor < 1).any():
            raise ConfigError(f"n_path and n_actor must be {n_lines} sample counts >= 1")
        if not isinstance(margin, int) or margin < 0:
            raise ConfigError(f"margin must be an integer >= 0, got {margin!r}")
        self._painter.path_blur(by_column, starts_ns, int(exposure_ns), n_path, n_actor, margin, out, hits)

    def reference_frame(self, t_ns: int, *, by_column: bool = False, linear: bool = False) -> RenderResult:
        """One full render with every line at ``t_ns`` and no shortcuts: every line painted over the bare
        background with every actor tested against it (no static-actor composite, no touched-line culling)."""
        n_lines, n_along = self.render_shape(by_column)
        t_s = np.array([np.int64(t_ns).astype(np.float64) * 1e-9])
        layer = self._composite.layers.get(by_column, t_s[0])
        p = self._painter.prepare(by_column, t_s, np.zeros(n_lines, np.int64), self._all, n_along, exhaustive=True)
        return self._composite.reference(p, layer, by_column, linear)

    def reference_lines(self, times_ns: np.ndarray, *, by_column: bool = False) -> RenderResult:
        """The study's brute-force method: one full render per line, keeping line r of render r.

        Each full render is ``reference_frame``, which shares only the bare background with the fast path,
        so the fast path's caches and culling are checked against it, not assumed.
        """
        times_ns = check_times(times_ns, self.render_shape(by_column)[0])
        n_lines = times_ns.shape[0]
        out: RenderResult | None = None
        for r in range(n_lines):
            full = self.reference_frame(int(times_ns[r]), by_column=by_column)
            if out is None:
                out = RenderResult(np.empty_like(full.image), None, LineTruth.empty(self.n_actors, n_lines, by_column))
            line = (slice(None), r) if by_column else r
            out.image[line] = full.image[line]
            for name in ("left", "right", "area", "visible"):
                getattr(out.truth, name)[:, r] = getattr(full.truth, name)[:, r]
        assert out is not None
        return out

    def object_truth(self, frame_truth: LineTruth, reference_time_ns: int, by_column: bool = False,
                     gs_truth: LineTruth | None = None) -> tuple[ObjectTruth, ...]:
        """Per-object ground truth of a frame: RS boxes from ``frame_truth``, GS boxes at the reference time
        (rendered unless ``gs_truth`` is given). Props and objects with no pixel under either shutter are left out."""
        if gs_truth is None:
            n_lines = self.render_shape(by_column)[0]
            gs_truth = self.render_lines(np.full(n_lines, reference_time_ns, np.int64), by_column=by_column,
                                         truth_only=True).truth
        return object_truths(frame_truth, gs_truth, self.actor_ids, self.actor_classes, self.actor_speeds_mps,
                             self.actor_labelled)


def check_times(times_ns: np.ndarray, n_lines: int) -> np.ndarray:
    """``times_ns`` as int64, one per line, or a ConfigError."""
    times_ns = np.asarray(times_ns, dtype=np.int64)
    if times_ns.shape != (n_lines,):
        raise ConfigError(f"need one time per line: {n_lines} lines, got times of shape {times_ns.shape}")
    return times_ns


def line_mask(lines: np.ndarray | None, n_lines: int) -> np.ndarray:
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


def _check_line_of(line_of: np.ndarray, n_ent: int, n_lines: int) -> np.ndarray:
    """``line_of`` as int64: one non-decreasing line index per sample, or a ConfigError."""
    line_of = np.asarray(line_of, np.int64)
    if line_of.shape != (n_ent,) or (n_ent and (line_of[0] < 0 or line_of[-1] >= n_lines
                                                or (np.diff(line_of) < 0).any())):
        raise ConfigError(f"line_of must hold one non-decreasing line index in 0..{n_lines - 1} per sample")
    return line_of


def check_buffers(out: np.ndarray, hits: np.ndarray | None, shape: tuple[int, int], need_hits: bool = False) -> None:
    """``out`` must be a C-contiguous float32 render-orientation buffer, ``hits`` (when given or needed) int64."""
    n_lines, n_along = shape
    if out.shape != (n_lines, n_along, 3) or out.dtype != np.float32 or not out.flags.c_contiguous:
        raise ConfigError(f"out must be a C-contiguous float32 array of shape {(n_lines, n_along, 3)}, "
                          f"got {out.dtype} {out.shape}")
    if (hits is not None or need_hits) and (hits is None or hits.shape != (n_lines,) or hits.dtype != np.int64):
        got = None if hits is None else f"{hits.dtype} {hits.shape}"
        raise ConfigError(f"hits must be an int64 array of {n_lines} counts, got {got}")
