"""Facade materials: brick, stone, plaster and glass curtain walls, their joints filtered over each pixel's
footprint, and glass reflecting what is across the street."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from rollcam.common.errors import ConfigError
from rollcam.sim import scenegen
from rollcam.sim.render import shader
from rollcam.sim.render.renderer import Renderer
from rollcam.sim.scene import FACADES, Building, Camera
from rollcam.sim.scenegen import make_street_scene

DOWN_THE_STREET = Camera("down", 640, 360, 4.0, 6.4, (0.0, -40.0, 1.6))
"""On the road's axis looking north: the west facades on the left of the image, the east ones on the right."""


def _street(seed: int, cam: Camera, by_side: dict[int, dict]) -> object:
    """Seed's street without walkers, seen by ``cam``, each side's buildings changed by ``by_side[side]``."""
    s = make_street_scene(seed, n_pedestrians=0, n_cameras=1)
    buildings = tuple(replace(b, **by_side.get(b.side, {})) for b in s.street.buildings)
    return replace(s, street=replace(s.street, buildings=buildings), cameras=(cam,))


def _linear(scene, width: int, height: int) -> np.ndarray:
    cam = scene.cameras[0].with_resolution(width, height)
    return Renderer(replace(scene, cameras=(cam,))).reference_frame(0, linear=True).image.astype(np.float64)


def test_pulse_cover_is_the_pulse_box_filtered_over_the_footprint() -> None:
    cover = shader.library().rollcam_pulse_cover
    rng = np.random.default_rng(3)
    for _ in range(60):
        p = float(rng.uniform(0.05, 3.0))
        w, h = float(rng.uniform(0.01, 0.5) * p), float(rng.uniform(1e-3, 4.0) * p)
        x = float(rng.uniform(-50.0, 50.0))
        s = np.linspace(x - h, x + h, 400_001)
        want = np.mean((s - np.floor(s / p) * p) < w)
        assert cover(x, h, p, w) == pytest.approx(want, abs=2e-4)
    # a footprint much smaller than the pulse samples it; one of many periods gives its duty cycle
    assert cover(0.05, 1e-7, 1.0, 0.1) == pytest.approx(1.0) and cover(0.5, 1e-7, 1.0, 0.1) == pytest.approx(0.0)
    assert cover(0.3, 500.0, 1.0, 0.1) == pytest.approx(0.1, abs=1e-3)


def test_an_unknown_facade_material_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match=r"material 'marble' is not one of \['plaster', 'brick'"):
        Building(side=1, y0_m=0.0, y1_m=10.0, height_m=12.0, color=(0.4, 0.4, 0.4), window_color=(0.1, 0.1, 0.1),
                 material="marble")


def test_materials_come_in_their_shares_and_leave_the_layout_alone(monkeypatch) -> None:
    scenes = [make_street_scene(seed, n_pedestrians=12, n_cameras=2, width=64, height=36) for seed in range(40)]
    buildings = [b for s in scenes for b in s.street.buildings]
    share = {m: np.mean([b.material == m for b in buildings]) for m in FACADES}
    tall = [b for b in buildings if b.height_m >= scenegen.GLASS_MIN_HEIGHT_M]
    assert len(buildings) > 800
    assert share["brick"] == pytest.approx(scenegen.BRICK_P, abs=0.04)
    assert share["stone"] == pytest.approx(scenegen.STONE_P, abs=0.03)
    assert np.mean([b.material == "glass" for b in tall]) == pytest.approx(scenegen.GLASS_P, abs=0.03)
    assert all(b.height_m >= scenegen.GLASS_MIN_HEIGHT_M for b in buildings if b.material == "glass")
    # drawn from their own stream: without them, each seed's buildings, walkers and cameras are where they were
    monkeypatch.setattr(scenegen, "_facades", lambda rng, b: b)
    for seed in (0, 7, 23):
        plain = make_street_scene(seed, n_pedestrians=12, n_cameras=2, width=64, height=36)
        assert plain.pedestrians == scenes[seed].pedestrians and plain.cameras == scenes[seed].cameras
        extents = [(b.side, b.y0_m, b.y1_m, b.height_m, b.floor_height_m, b.window_spacing_m)
                   for b in scenes[seed].street.buildings]
        assert extents == [(b.side, b.y0_m, b.y1_m, b.height_m, b.floor_height_m, b.window_spacing_m)
                           for b in plain.street.buildings]
        assert {b.material for b in plain.street.buildings} == {"plaster"}


@pytest.mark.parametrize("material", ["brick", "glass"])
def test_joints_and_mullions_are_filtered_not_aliased(material) -> None:
    # A quarter-size render sees the same wall as the 4x4 mean of the full-size one (up to the shading's own
    # sampling, which the plaster baseline measures): brick courses and mullions thinner than a pixel shade it
    # by their area. Unfiltered (point-sampled) joints had 2.8x the plaster's error on brick, 1.04x on glass.
    def error(mat: str) -> float:
        scene = _street(3, DOWN_THE_STREET, {1: {"material": mat}, -1: {"material": mat}})
        big, small = _linear(scene, 1920, 1080), _linear(scene, 480, 270)
        mean4 = big.reshape(270, 4, 480, 4, 3).mean(axis=(1, 3))
        wall = (slice(0, 150), slice(None))  # above the sidewalks: facades and a little sky
        return float(np.abs(mean4 - small)[wall].mean() / small[wall].mean())

    plaster = error("plaster")
    assert error(material) < (1.6 if material == "brick" else 0.8) * plaster


def test_brick_has_courses_and_stone_blocks() -> None:
    # Straight at the east facade from the road: the wall's rows repeat every brick course (75 mm), so the
    # vertical profile of a brick wall varies far more from row to row than a plaster one.
    facing = Camera("facing", 640, 360, 4.0, 6.4, (0.0, 0.0, 6.0), yaw_deg=90.0)

    def row_variation(mat: str) -> float:
        img = _linear(_street(1, facing, {1: {"material": mat}}), 640, 360).mean(axis=2)
        return float(np.abs(np.diff(img, axis=0)).mean() / img.mean())

    plaster, brick, stone = row_variation("plaster"), row_variation("brick"), row_variation("stone")
    assert brick > 2.0 * plaster and stone > 1.1 * plaster


def test_glass_reflects_the_facade_across_the_street() -> None:
    east = (slice(0, 160), slice(480, 640))  # the east facades, above the sidewalk
    white, black = (0.8, 0.8, 0.8), (0.03, 0.03, 0.03)

    def seen(east_mat: str, west_rgb: tuple) -> np.ndarray:
        scene = _street(3, DOWN_THE_STREET, {1: {"material": east_mat}, -1: {"material": "plaster",
                                                                              "color": west_rgb}})
        return _linear(scene, 640, 360)[east]

    # the premise: that corner of the image is the east side's
    bright_east = _linear(_street(3, DOWN_THE_STREET, {1: {"color": white}, -1: {"color": black}}), 640, 360)
    dark_east = _linear(_street(3, DOWN_THE_STREET, {1: {"color": black}, -1: {"color": white}}), 640, 360)
    assert bright_east[east].mean() > 1.8 * dark_east[east].mean()
    # a curtain wall mirrors the west facades over most of its panes; plaster only in its windows
    glass = seen("glass", white) - seen("glass", black)
    plaster = seen("plaster", white) - seen("plaster", black)
    assert glass.min() >= 0.0 and plaster.min() >= 0.0
    assert (glass.sum(axis=2) > 0).mean() > 0.6 and 0.05 < (plaster.sum(axis=2) > 0).mean() < 0.35
    assert glass.mean() > 5.0 * plaster.mean()
