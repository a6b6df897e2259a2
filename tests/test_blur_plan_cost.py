"""The blur plan's and the integration's shortcuts give what the work they skip would have given."""

from __future__ import annotations

import numpy as np
import pytest
from rollcam.common.errors import ConfigError
from rollcam.sim.exposure import (
    BOUND_LINES,
    EGO_SAMPLES,
    SamplePlan,
    dense_plan,
    integrate,
    plan_samples,
    touching_lines,
)
from rollcam.sim.hwconfig import load_sensor
from rollcam.sim.render import Renderer, srgb_lut
from rollcam.sim.scenegen import ego_preset, make_street_scene
from rollcam.sim.synthetic import SyntheticCamera


def _unscreened_touch(r: Renderer, starts: np.ndarray, exposure_ns: int, by_column: bool) -> np.ndarray:
    """Which moving actor touches which line the long way: every moving actor's swept box on every line."""
    n_lines, n_along = r.render_shape(by_column)
    need = np.zeros((r.n_actors, n_lines), np.bool_)
    need[r.moving_actors] = True
    b = r.actor_bounds(starts * 1e-9, np.full(n_lines, exposure_ns * 1e-9), need, by_column=by_column)
    centre = np.arange(n_lines) + 0.5
    touch = np.zeros_like(need)
    for o in r.moving_actors:
        touch[o] = (b[o, :, 0] <= centre) & (centre <= b[o, :, 1]) & (b[o, :, 2] < n_along) & (b[o, :, 3] > 0)
    return touch


def _actor_rule_speeds(r: Renderer, starts: np.ndarray, exposure_ns: int) -> np.ndarray:
    """The plan's per-line speed before part speeds: the fastest part of every actor touching the line."""
    t0, t1 = int(starts.min()), int(starts.max()) + exposure_ns
    n_t = max(2, -(-(t1 - t0) // 250_000) + 1)
    act_speed = r.actor_image_speeds(np.linspace(t0 * 1e-9, t1 * 1e-9, n_t))
    touch = _unscreened_touch(r, starts, exposure_ns, False)
    return np.where(touch, act_speed[:, None], 0.0).max(axis=0, initial=0.0)


@pytest.mark.parametrize("by_column", [False, True])
def test_screened_touching_lines_equal_every_per_line_bound(by_column: bool) -> None:
    scene = make_street_scene(3, speed="fast", width=480, height=270, n_pedestrians=20)
    r = Renderer(scene)
    n_lines = r.render_shape(by_column)[0]
    assert n_lines > 4 * BOUND_LINES
    exposure_ns = 10_000_000
    for k in range(3):
        starts = 1_000_000_000 + 33_333_333 * k + np.arange(n_lines, dtype=np.int64) * 18_903
        starts = starts[::-1].copy() if by_column else starts  # a readout from the far edge: decreasing starts
        got = touching_lines(r, starts, exposure_ns, by_column=by_column)
        ref = _unscreened_touch(r, starts, exposure_ns, by_column)
        assert ref.any() and not ref.all()
        np.testing.assert_array_equal(got, ref)
    with pytest.raises(ConfigError, match="one window start per line"):
        touching_lines(r, starts[:-1], exposure_ns, by_column=by_column)


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


def _srgb(r: Renderer, lin: np.ndarray) -> np.ndarray:
    lut = srgb_lut()
    return lut[(np.clip(lin * r.gain, 0, 1) * (lut.size - 1) + 0.5).astype(np.int64)].astype(float)


def test_part_speeds_cut_the_samples_and_keep_the_error_near_the_actor_rule() -> None:
    # Each line is sampled for the fastest part that can reach it, not the fastest part of every actor touching
    # it: against the actor rule (the plan before), fewer samples, and against the dense reference (0.05 px
    # steps) an error that stays a few thousandths of a DN on average and at most 1 DN at the 99.9th percentile.
    scene = make_street_scene(3, speed="fast", width=480, height=270, n_pedestrians=20)
    cam = SyntheticCamera(load_sensor("imx219"), scene, size=(480, 270))
    r, exposure = cam.renderer, cam.settings.exposure_ns
    starts = cam.line_times_ns(2) - exposure // 2
    plan = plan_samples(r, starts, exposure)
    speed = _actor_rule_speeds(r, starts, exposure)
    np.testing.assert_array_equal(plan_samples(r, starts, exposure, part_speeds=False).speed_px_s, speed)
    actor_rule = SamplePlan(plan.starts_ns, exposure, np.clip(np.ceil(speed * exposure * 1e-9 / 0.5), 1, 512
                                                               ).astype(np.int64), speed, False, plan.grid_ns)
    assert (plan.n > actor_rule.n).mean() < 0.1  # a turning texture or the power of two may ask more on a few lines
    assert plan.evaluations <= 0.9 * actor_rule.evaluations, (plan.evaluations, actor_rule.evaluations)
    more = plan.n[plan.n > actor_rule.n]
    assert ((more & (more - 1)) == 0).all()  # a part speed's count is a power of two
    ref = _srgb(r, integrate(r, dense_plan(actor_rule, 0.05)).linear)
    err = np.abs(_srgb(r, integrate(r, plan).linear) - ref)
    err_actor = np.abs(_srgb(r, integrate(r, actor_rule).linear) - ref)
    assert err.mean() <= max(3.0 * err_actor.mean(), 0.005), (err.mean(), err_actor.mean())
    assert np.percentile(err, 99.9) <= 1.0


@pytest.mark.parametrize("ego", ["walk", "drone"])
def test_a_moving_camera_keeps_the_per_actor_rule(ego: str) -> None:
    # Every line of a moving camera moves (and is capped): part speeds would change nothing worth their cost.
    scene = make_street_scene(1, speed="fast", width=320, height=180, n_pedestrians=12, ego=ego_preset(ego))
    r = Renderer(scene)
    starts = 1_000_000_000 + np.arange(180, dtype=np.int64) * 75_000
    odd = False  # some count that a power of two would change
    for bound in (0.5, 1.0, 2.0, 5.0):
        parts = plan_samples(r, starts, 10_000_000, bound_px=bound)
        actors = plan_samples(r, starts, 10_000_000, bound_px=bound, part_speeds=False)
        np.testing.assert_array_equal(parts.n, actors.n)
        np.testing.assert_array_equal(parts.speed_px_s, actors.speed_px_s)
        rule = np.clip(np.ceil(parts.speed_px_s * 10_000_000e-9 / bound), 1, EGO_SAMPLES)
        np.testing.assert_array_equal(parts.n, rule)  # the bound's own counts, no power of two
        odd |= bool(np.isin(rule, (3, 5, 6, 7)).any())
    assert odd
