"""The renderer's fast paths against their references: every ego-motion preset's exact RS frame against the
brute-force renders, serial against threaded kernels, and the background's exact shortcuts (noise-cell reuse,
the fog table) against the plain functions."""

from __future__ import annotations

import math
import threading

import numba
import numpy as np
import pytest
from rollcam.sim import _actors, _kernels, _shade, _world
from rollcam.sim.render import Renderer
from rollcam.sim.scenegen import ego_preset, make_street_scene


def _rs_times(renderer: Renderer, t0_ns: int, line_ns: int = 31_000) -> np.ndarray:
    return t0_ns + line_ns * np.arange(renderer.render_shape()[0], dtype=np.int64)


@pytest.mark.parametrize("ego", ["none", "pan", "walk", "vehicle", "drone"])
def test_exact_rs_equals_brute_force_for_every_ego_preset(ego: str) -> None:
    scene = make_street_scene(3, speed="fast", width=96, height=54, n_pedestrians=20, ego=ego_preset(ego))
    r = Renderer(scene)
    times = _rs_times(r, 1_234_567_891)
    fast = r.render_lines(times)
    ref = r.reference_lines(times)
    assert np.abs(fast.image.astype(int) - ref.image.astype(int)).max() <= 1
    assert fast.truth.boxes() == ref.truth.boxes()


@pytest.mark.parametrize("ego", ["none", "drone"])
def test_threaded_kernels_paint_what_the_serial_ones_do(ego: str) -> None:
    scene = make_street_scene(5, speed="normal", width=640, height=360, n_pedestrians=20, ego=ego_preset(ego))
    times = _rs_times(Renderer(scene), 2_000_000_000)
    serial = Renderer(scene, threads=1).render_lines(times, linear=True)
    threaded = Renderer(scene, threads=max(numba.config.NUMBA_NUM_THREADS, 2)).render_lines(times, linear=True)
    assert np.array_equal(serial.image, threaded.image)
    assert np.array_equal(serial.linear, threaded.linear)


# Every kernel Python calls (sim/_paint.py): each releases the GIL while it runs.
_ENTRY_KERNELS = (_kernels.render_lines_kernel, _kernels.render_lines_par, _kernels.touch_entries,
                  _kernels.part_slots, _actors.actor_bounds_all, _actors.actor_bounds_par, _actors.actor_parts_all,
                  _actors.actor_parts_par, _actors.actor_speeds, _world.pose_table, _world.background_image)


def test_kernels_called_from_python_release_the_gil() -> None:
    held = [k.py_func.__name__ for k in _ENTRY_KERNELS if not k.targetoptions.get("nogil")]
    assert held == []


@pytest.mark.parametrize("ego", ["none", "vehicle"])
def test_renders_on_two_threads_at_once_equal_serial_renders(ego: str) -> None:
    # The kernels release the GIL, so these renders overlap (parallel ones take turns under one lock).
    scene = make_street_scene(2, speed="fast", width=320, height=180, n_pedestrians=20, ego=ego_preset(ego))
    r0 = Renderer(scene)
    starts = [1_000_000_000 + 33_000_000 * i for i in range(6)]
    want = [r0.render_lines(_rs_times(r0, t)).image for t in starts]
    got: dict[int, np.ndarray] = {}

    def run(part: list[int], threads: int | None) -> None:
        r = Renderer(scene, threads=threads)
        for i in part:
            got[i] = r.render_lines(_rs_times(r, starts[i])).image

    workers = [threading.Thread(target=run, args=([0, 2, 4], 1)), threading.Thread(target=run, args=([1, 3, 5], None))]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    assert all(np.array_equal(got[i], want[i]) for i in range(6))


def test_renderer_threads_must_be_a_positive_count() -> None:
    scene = make_street_scene(0, width=32, height=18, n_pedestrians=0)
    with pytest.raises(ValueError, match="threads must be"):
        Renderer(scene, threads=0)


@numba.njit
def _noise_both_ways(xs, ys, seed):
    """Value noise along a path with the cell reused between points, and afresh at every point."""
    reused, fresh = np.empty(xs.size), np.empty(xs.size)
    cell = _shade.NO_CELL
    for i in range(xs.size):
        reused[i], cell = _shade.value_noise(xs[i], ys[i], seed, cell)
        fresh[i], _ = _shade.value_noise(xs[i], ys[i], seed, _shade.NO_CELL)
    return reused, fresh


def test_noise_cell_reuse_is_exact() -> None:
    rng = np.random.default_rng(0)
    # A slow path (long runs in one cell), a fast one (a new cell nearly every point) and negative coordinates.
    xs = np.concatenate([np.linspace(-3.0, 5.0, 4000), rng.uniform(-50, 50, 500)])
    ys = np.concatenate([np.linspace(7.0, -2.0, 4000), rng.uniform(-50, 50, 500)])
    for seed in (0, 11, 2**31 - 1):
        reused, fresh = _noise_both_ways(xs, ys, seed)
        assert np.array_equal(reused, fresh)
        assert fresh.min() >= 0.0 and fresh.max() < 1.0


@numba.njit
def _fog(xs):
    out = np.empty(xs.size)
    for i in range(xs.size):
        out[i] = _shade.fog_transmittance(xs[i])
    return out


def test_fog_table_matches_exp() -> None:
    xs = np.concatenate([np.linspace(0.0, 70.0, 200_001), [63.999, 64.0, 1e6]])
    got = _fog(xs)
    want = np.exp(-xs)
    assert np.all(np.abs(got - want) <= 1e-10 * want + 1e-27)
    assert got[-1] == 0.0 and math.isclose(got[0], 1.0)


def test_part_slots_share_a_time_used_by_several_entries_and_leave_single_uses_local() -> None:
    from rollcam.sim import _kernels as K

    rng = np.random.default_rng(5)
    obj_k = rng.integers(-1, 6, (7, 40)).astype(np.int64)
    obj_k[2] = -1  # an actor touching nothing
    obj_k[3, :] = -1
    obj_k[3, 4] = 2  # used by one entry only
    slots = np.empty((7, 6), np.int64)
    s_o, s_k = K.part_slots(obj_k, 6, slots)
    uses = np.zeros((7, 6), np.int64)
    for o, e in zip(*np.nonzero(obj_k >= 0), strict=True):
        uses[o, obj_k[o, e]] += 1
    assert (slots[uses == 0] == K.SLOT_NONE).all() and (slots[uses == 1] == K.SLOT_LOCAL).all()
    assert slots[3, 2] == K.SLOT_LOCAL
    shared_o, shared_k = np.nonzero(uses > 1)  # row-major, as the table's rows
    assert np.array_equal(s_o, shared_o) and np.array_equal(s_k, shared_k)
    assert np.array_equal(slots[shared_o, shared_k], np.arange(shared_o.size))
