"""What walkers carry and wear beyond shirt and trousers: bags (backpack, shoulder bag) and skirts."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from rollcam.common.errors import ConfigError
from rollcam.sim import scenegen
from rollcam.sim.render import actors as A
from rollcam.sim.render import body as B
from rollcam.sim.render.renderer import Renderer
from rollcam.sim.scene import BAGS
from rollcam.sim.scenegen import BACKPACK_P, SHOULDER_BAG_P, SKIRT_P, ego_preset, make_street_scene
from test_render import _assert_parts_inside


def _dressed(scene, **outfit):
    """The scene with every walker in the same outfit."""
    return replace(scene, pedestrians=tuple(replace(p, **outfit) for p in scene.pedestrians))


def _live(parts: np.ndarray) -> np.ndarray:
    return (parts[..., A.Q_KIND] == A.PART_CAPSULE).sum(axis=-1)


def test_bag_kinds_match_the_kernel_codes_and_a_wrong_one_is_refused() -> None:
    assert [BAGS.index(k) for k in ("none", "backpack", "shoulder")] == [B.BAG_NONE, B.BAG_BACKPACK, B.BAG_SHOULDER]
    p = make_street_scene(0, width=64, height=36, n_pedestrians=1).pedestrians[0]
    with pytest.raises(ConfigError, match="bag 'purse' is not one of"):
        replace(p, bag="purse")


def test_a_bag_is_one_more_capsule_in_its_own_colour_and_a_skirt_bares_the_shins() -> None:
    scene = make_street_scene(2, width=640, height=360, n_pedestrians=6, props=False)
    times = np.linspace(0.0, 20.0, 9)
    plain = Renderer(_dressed(scene, bag="none", skirt=False)).actor_parts(times)
    red = (0.4, 0.05, 0.05)
    for kind in ("backpack", "shoulder"):
        bag = Renderer(_dressed(scene, bag=kind, bag_rgb=red, skirt=False)).actor_parts(times)
        drawn = _live(plain) == 18  # whole walkers (none clipped at the near plane)
        assert drawn.any()
        np.testing.assert_array_equal(_live(bag)[drawn], 19)
        # the 19th capsule is lit as the others are, with the bag's albedo
        hand, extra = plain[..., 17, :], bag[..., 18, :]
        skin = np.array([p.skin for p in scene.pedestrians])[:, None, :]
        light = hand[..., A.Q_AMB : A.Q_AMB + 3] / skin
        np.testing.assert_allclose(extra[..., A.Q_AMB : A.Q_AMB + 3][drawn], (light * red)[drawn], rtol=1e-12)
        used = np.r_[: A.Q_GEO + 5, A.Q_YMIN : A.PART_COLS]  # a capsule's columns (the rest is a quad's)
        np.testing.assert_array_equal(bag[..., :18, used][drawn], plain[..., :18, used][drawn])  # the same body
    skirt = Renderer(_dressed(scene, bag="none", skirt=True)).actor_parts(times)
    pelvis, shins = 5, (7, 13)  # after head, hair, neck, abdomen, chest; then thigh, shin, foot, arm, forearm, hand
    assert (skirt[..., pelvis, A.Q_GEO + 4] > plain[..., pelvis, A.Q_GEO + 4])[drawn].all()  # wider than the pelvis
    for s in shins:  # skin-coloured, as the neck is
        np.testing.assert_allclose(skirt[..., s, A.Q_AMB : A.Q_AMB + 3][drawn],
                                   skirt[..., 2, A.Q_AMB : A.Q_AMB + 3][drawn], rtol=1e-12)
        np.testing.assert_array_equal(plain[..., s, A.Q_AMB][drawn] != skirt[..., s, A.Q_AMB][drawn], True)


@pytest.mark.parametrize("outfit", [{"bag": "backpack"}, {"bag": "shoulder"}, {"bag": "none", "skirt": True}])
def test_bounds_contain_bags_and_skirts_on_the_widest_walkers(outfit: dict) -> None:
    """The touched-line bounds are the body's reach: a bag or skirt on the heaviest build stays inside them."""
    for seed, ego in ((1, "none"), (3, "vehicle")):
        scene = make_street_scene(seed, speed="fast", width=320, height=180, n_pedestrians=20, ego=ego_preset(ego))
        scene = replace(scene, pedestrians=tuple(replace(p, build=1.3, **outfit) for p in scene.pedestrians))
        for cam_i in range(len(scene.cameras)):
            r = Renderer(scene, cam_i)
            times = np.linspace(0.0, 40.0, 31)
            parts = r.actor_parts(times)
            boxes = r.actor_bounds(times, np.zeros(times.size), np.ones((r.n_actors, times.size), np.bool_))
            for i in range(times.size):
                for o in range(r.n_actors):
                    live = parts[o, i, :, A.Q_KIND] != A.PART_NONE
                    if boxes[o, i, 0] > boxes[o, i, 1]:
                        assert not live.any()
                    elif live.any():
                        _assert_parts_inside(boxes[o, i], parts[o, i], live)


def test_outfitted_walkers_render_exactly_and_their_truth_counts_the_bag() -> None:
    scene = _dressed(make_street_scene(4, speed="fast", width=160, height=90, n_pedestrians=12), bag="backpack")
    r = Renderer(scene)
    times = (np.arange(90, dtype=np.int64) * 30_000 + 1_500_000_000).astype(np.int64)
    fast = r.render_lines(times)
    ref = r.reference_lines(times)
    assert np.abs(fast.image.astype(int) - ref.image.astype(int)).max() <= 1
    assert fast.truth.boxes() == ref.truth.boxes()
    bare = Renderer(_dressed(scene, bag="none")).render_lines(times)
    assert fast.truth.area.sum() > bare.truth.area.sum()  # the backpack's pixels are the walker's


def test_street_outfits_come_in_their_shares_and_leave_the_layout_alone() -> None:
    walkers = [p for seed in range(12) for p in make_street_scene(seed, width=64, height=36).pedestrians]
    n = len(walkers)
    bags = [p.bag for p in walkers]
    for kind, share in (("backpack", BACKPACK_P), ("shoulder", SHOULDER_BAG_P)):
        assert abs(bags.count(kind) / n - share) < 4 * np.sqrt(share / n)
    adults = [p for p in walkers if p.height_m >= 1.45]
    assert abs(sum(p.skirt for p in adults) / len(adults) - SKIRT_P) < 4 * np.sqrt(SKIRT_P / len(adults))
    assert not any(p.skirt for p in walkers if p.height_m < 1.45)
    # the outfits' own stream: a seed's street, cameras and walkers are what they were without outfits
    bare = make_street_scene(7, width=64, height=36)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(scenegen, "_outfits", lambda rng, peds: peds)
        plain = make_street_scene(7, width=64, height=36)
    assert (bare.street, bare.cameras) == (plain.street, plain.cameras)
    assert any(p.bag != "none" for p in bare.pedestrians)
    default = {"bag": "none", "bag_rgb": plain.pedestrians[0].bag_rgb, "skirt": False}
    assert [replace(p, **default) for p in bare.pedestrians] == list(plain.pedestrians)
