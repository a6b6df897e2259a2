"""The renderer of a scene with modulated lights: steady light plus each light's render, weighted line by line.

Radiance is linear in light, so a scene lit by steady light and by lights ``L_1..L_C`` that change in time is,
on line ``l``, ``R_0(l) + sum_c w_c(l) R_c(l)``: ``R_0`` the scene under its steady light alone, ``R_c`` the
scene lit by light c alone at its mean output, and ``w_c(l)`` the exact mean of light c's waveform over line
l's exposure window (``rollcam.sim.flicker``). Each ``R`` is an ordinary ``Renderer`` over a derived scene
(``light_scene``), with its own static caches, touched-line culling and exact per-line times, so the hot kernels
do nothing new and a scene without modulated lights renders exactly as before. The weights are computed once
per line and light, outside any per-pixel code; ``flicker_mix`` joins the renders.

The window of a line rendered at time t is ``[t - w/2, t - w/2 + w]`` with w the renderer's
``light_window_ns`` (the exposure: a ``SyntheticCamera`` samples each line mid-exposure); exposure integration
(``rollcam.sim.exposure.integrate``) weights each light's time-averaged render by its mean over the line's
whole window (exact for everything that holds still; for a moving walker the product of the two means).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from rollcam.common.errors import ConfigError

from ..scene import Camera, Lighting, ModulatedLight, Scene
from . import flicker_mix as M
from .renderer import SRGB, Renderer, check_buffers, check_times, line_mask, register_lit_renderer
from .result import LinearFrame, RenderResult


def light_scene(scene: Scene, light: ModulatedLight | None) -> Scene:
    """``scene`` lit by ``light`` alone at its mean output (None: by the steady light alone)."""
    if light is None:
        return replace(scene, lights=())
    li = scene.lighting
    only = Lighting(li.name, 0.0, 90.0, light.overhead_rgb, light.ambient_rgb, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                    (0.0, 0.0, 0.0), li.fog_distance_m, light.glow)
    return replace(scene, lighting=only, flat_level=light.level, lights=())


class FlickerRenderer(Renderer):
    """A ``Renderer`` of a scene with modulated lights (``Renderer(scene)`` builds one when ``scene.lights``).

    Geometry (poses, bounds, actor parts, truth) is the scene's own; every image is the weighted sum of the
    plain renders in ``parts`` (steady light first, then one per light).
    """

    def __init__(self, scene: Scene, camera: Camera | int | str = 0, *, gain: float = 1.0,
                 threads: int | None = None, light_window_ns: int = 0) -> None:
        if scene.kind == "chart":
            raise ConfigError("a chart's board is unlit: modulated lights apply to street, flat and flicker scenes")
        super().__init__(scene, camera, gain=gain, threads=threads, light_window_ns=light_window_ns)
        self.lights = scene.lights
        self.parts = tuple(Renderer(light_scene(scene, li), self.camera, gain=gain, threads=threads)
                           for li in (None, *scene.lights))
        self._scratch: dict[bool, np.ndarray] = {}
        self._static_stack: dict[bool, tuple[tuple[int, ...], np.ndarray]] = {}

    def line_weights(self, t0_ns: np.ndarray, t1_ns: np.ndarray) -> np.ndarray:
        """``(parts, lines)`` weights: 1 for the steady light, each light's mean over ``[t0, t1]`` after."""
        w = np.ones((len(self.parts), np.shape(t0_ns)[0]))
        for c, li in enumerate(self.lights):
            w[c + 1] = li.waveform.window_mean(t0_ns, t1_ns)
        return w

    def window_weights(self, times_ns: np.ndarray) -> np.ndarray:
        """Weights of lines rendered at ``times_ns``: windows of ``light_window_ns`` centred on them."""
        t0 = np.asarray(times_ns, np.int64) - self.light_window_ns // 2
        return self.line_weights(t0, t0 + self.light_window_ns)

    def scratch(self, k: int, by_column: bool) -> np.ndarray:
        """Part ``k``'s slot (float32, render orientation) of the reusable stack the parts render into."""
        stack = self._scratch.get(by_column)
        if stack is None:
            shape = (len(self.parts), *self.render_shape(by_column), 3)
            stack = self._scratch[by_column] = np.empty(shape, np.float32)
        return stack[k]

    def join(self, frames: list[LinearFrame], weights: np.ndarray, which: np.ndarray, out: np.ndarray,
             out_u8: np.ndarray | None = None) -> None:
        """``out[l] = sum_k weights[k, l] * frames[k][l]`` on lines ``which`` (and their 8-bit encoding), in
        one pass: the parts' painted lines are read from the stack they were rendered into, their static
        composites from one stacked copy made on first use (they never change)."""
        by_column = frames[0].by_column
        lines = self._scratch.get(by_column)
        if lines is None or any(f.lines.ctypes.data != lines[k].ctypes.data for k, f in enumerate(frames)):
            lines = np.stack([f.lines for f in frames])  # renders made elsewhere (the brute-force reference)
        statics = lines if frames[0].static is None else self._statics(frames, by_column)
        painted = np.stack([f.painted for f in frames])
        u8 = np.empty((0, 1, 3), np.uint8) if out_u8 is None else out_u8
        M.join_lines(out, statics, lines, painted, weights, np.asarray(which, np.int64), self.gain, SRGB, u8)

    def _statics(self, frames: list[LinearFrame], by_column: bool) -> np.ndarray:
        """The parts' static composites as one ``(parts, lines, along, 3)`` array, copied once per orientation."""
        ptrs = tuple(f.static.ctypes.data for f in frames)
        hit = self._static_stack.get(by_column)
        if hit is None or hit[0] != ptrs:
            hit = self._static_stack[by_column] = (ptrs, np.stack([f.static for f in frames]))
        return hit[1]

    # ------------------------------------------------------------------ the renders, as sums of the parts' renders
    def render_lines(self, times_ns: np.ndarray, *, by_column: bool = False, linear: bool = False,
                     truth_only: bool = False) -> RenderResult:
        """``Renderer.render_lines`` under the modulated lights (each line's light over its own window)."""
        times_ns = check_times(times_ns, self.render_shape(by_column)[0])
        if truth_only:
            return self.parts[0].render_lines(times_ns, by_column=by_column, truth_only=True)
        res = [p.render_linear(times_ns, by_column=by_column, out=self.scratch(k, by_column))
               for k, p in enumerate(self.parts)]
        shape = self.render_shape(by_column)
        lin, u8 = np.empty((*shape, 3), np.float32), np.empty((*shape, 3), np.uint8)
        self.join([r.radiance for r in res], self.window_weights(times_ns), np.arange(shape[0]), lin, u8)
        return RenderResult(_oriented(u8, by_column, True), _oriented(lin, by_column, False) if linear else None,
                            res[0].truth, res[0].lines_painted)

    def render_linear(self, times_ns: np.ndarray, *, by_column: bool = False, lines: np.ndarray | None = None,
                      out: np.ndarray | None = None, hits: np.ndarray | None = None) -> RenderResult:
        """``Renderer.render_linear`` under the modulated lights: every asked-for line is written to ``out``
        (no shared composite: the lines' light differs). Accumulation (``hits``) is ``exposure.integrate``'s."""
        if hits is not None:
            raise ConfigError("under modulated lights, accumulate exposures with rollcam.sim.exposure.integrate")
        n_lines, n_along = self.render_shape(by_column)
        times_ns = check_times(times_ns, n_lines)
        subset = line_mask(lines, n_lines)
        res = [p.render_linear(times_ns, by_column=by_column, lines=subset, out=self.scratch(k, by_column))
               for k, p in enumerate(self.parts)]
        out = np.empty((n_lines, n_along, 3), np.float32) if out is None else out
        check_buffers(out, None, (n_lines, n_along))
        self.join([r.radiance for r in res], self.window_weights(times_ns), np.flatnonzero(subset), out)
        frame = LinearFrame(None, out, subset.copy(), by_column)
        return RenderResult(np.empty((0, 0, 3), np.uint8), None, res[0].truth, res[0].lines_painted, frame)

    def accumulate_samples(self, times_ns, line_of, out, hits, *, by_column=False):
        """Not per sample under modulated lights: ``rollcam.sim.exposure.integrate`` weights whole windows."""
        raise ConfigError("under modulated lights, accumulate exposures with rollcam.sim.exposure.integrate")

    def reference_frame(self, t_ns: int, *, by_column: bool = False, linear: bool = False) -> RenderResult:
        """``Renderer.reference_frame`` under the modulated lights: every part's brute-force render, joined."""
        n_lines = self.render_shape(by_column)[0]
        res = [p.reference_frame(t_ns, by_column=by_column, linear=True) for p in self.parts]
        frames = [LinearFrame(None, _render_side(r.linear, by_column), np.ones(n_lines, np.bool_), by_column)
                  for r in res]
        shape = self.render_shape(by_column)
        lin, u8 = np.empty((*shape, 3), np.float32), np.empty((*shape, 3), np.uint8)
        self.join(frames, self.window_weights(np.full(n_lines, t_ns, np.int64)), np.arange(n_lines), lin, u8)
        return RenderResult(_oriented(u8, by_column, True), _oriented(lin, by_column, False) if linear else None,
                            res[0].truth, n_lines)


def _oriented(a: np.ndarray, by_column: bool, contiguous: bool) -> np.ndarray:
    a = a.transpose(1, 0, 2) if by_column else a
    return np.ascontiguousarray(a) if contiguous else a

def _render_side(a: np.ndarray, by_column: bool) -> np.ndarray:
    """An image-orientation array back in render orientation (C-contiguous)."""
    return np.ascontiguousarray(a.transpose(1, 0, 2) if by_column else a)


register_lit_renderer(FlickerRenderer)  # Renderer(scene) of a scene with modulated lights is one
