"""The blur plan's and the integration's shortcuts give what the work they skip would have given."""

from __future__ import annotations

import numpy as np
import pytest
from rollcam.common.errors import ConfigError
from rollcam.sim.exposure import BOUND_LINES, plan_samples
from rollcam.sim.render import Renderer
from rollcam.sim.scenegen import make_street_scene


def _unscreened_speeds(r: Renderer, starts: np.ndarray, exposure_ns: int, by_column: bool) -> np.ndarray:
    """The plan's per-line image speed the long way: every moving actor's swept box on every line, every actor's
    speed (what ``plan_samples`` computed before it screened pairs by line group and skipped unseen actors)."""
    n_lines, n_along = r.render_shape(by_column)
    exp_s = exposure_ns * 1e-9
    t0, t1 = int(starts.min()), int(starts.max()) + exposure_ns
    n_t = max(2, -(-(t1 - t0) // 250_000) + 1)
    act_speed = r.actor_image_speeds(np.linspace(t0 * 1e-9, t1 * 1e-9, n_t), by_column=by_column)
    need = np.zeros((r.n_actors, n_lines), np.bool_)
    need[r.moving_actors] = True
    b = r.actor_bounds(starts * 1e-9, np.full(n_lines, exp_s), need, by_column=by_column)
    centre = np.arange(n_lines) + 0.5
    speed = np.zeros(n_lines)
    for o in r.moving_actors:
        touch = (b[o, :, 0] <= centre) & (centre <= b[o, :, 1]) & (b[o, :, 2] < n_along) & (b[o, :, 3] > 0)
        speed[touch] = np.maximum(speed[touch], act_speed[o])
    return speed


@pytest.mark.parametrize("by_column", [False, True])
def test_plan_speeds_equal_the_unscreened_per_line_bounds(by_column: bool) -> None:
    scene = make_street_scene(3, speed="fast", width=480, height=270, n_pedestrians=20)
    r = Renderer(scene)
    n_lines = r.render_shape(by_column)[0]
    assert n_lines > 4 * BOUND_LINES
    exposure_ns = 10_000_000
    for k in range(3):
        starts = 1_000_000_000 + 33_333_333 * k + np.arange(n_lines, dtype=np.int64) * 18_903
        starts = starts[::-1].copy() if by_column else starts  # a readout from the far edge: decreasing starts
        plan = plan_samples(r, starts, exposure_ns, by_column=by_column)
        ref = _unscreened_speeds(r, starts, exposure_ns, by_column)
        assert (ref > 0).any() and (ref == 0).any()  # some lines touched, some not
        np.testing.assert_array_equal(plan.speed_px_s, ref)


def test_actor_speeds_of_chosen_actors_equal_all_actors_speeds() -> None:
    r = Renderer(make_street_scene(1, speed="fast", width=320, height=180, n_pedestrians=12))
    times = np.linspace(1.0, 1.03, 121)
    every = r.actor_image_speeds(times)
    pick = np.zeros(r.n_actors, np.bool_)
    pick[::3] = True
    some = r.actor_image_speeds(times, actors=pick)
    np.testing.assert_array_equal(some[pick], every[pick])
    assert (some[~pick] == 0).all() and (every[pick] > 0).any()
    np.testing.assert_array_equal(r.actor_image_speeds(times, actors=np.flatnonzero(pick)), some)
    with pytest.raises(ConfigError, match="actor mask"):
        r.actor_image_speeds(times, actors=np.ones(r.n_actors + 1, np.bool_))
    with pytest.raises(ConfigError, match="actor indices"):
        r.actor_image_speeds(times, actors=np.array([r.n_actors]))
