"""Street props: scene data apart from the rest of the scene, placed clear of walkers and cameras, drawn exactly
(fast path against the brute-force reference, bounds containing every part, near-plane clipping), hiding the
walkers behind them, and never reported as objects."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from rollcam.sim.instance_masks import render_masks
from rollcam.sim.render import actors as A
from rollcam.sim.render.renderer import Renderer
from rollcam.sim.render.tables import compile_scene
from rollcam.sim.scene import PROP_KINDS, Camera, Prop
from rollcam.sim.scenegen import ego_preset, make_street_scene
from rollcam.sim.streetprops import CAMERA_CLEARANCE_M, _distance, _footprint, _lane_footprint, _overlaps


def _rs_times(n_lines: int, t0_ns: int, line_ns: int = 31_000) -> np.ndarray:
    return t0_ns + line_ns * np.arange(n_lines, dtype=np.int64)


def test_props_leave_the_rest_of_the_scene_as_it_was() -> None:
    for seed in (0, 7, 2**63 + 5):
        plain, cluttered = make_street_scene(seed), make_street_scene(seed, props=True)
        assert plain.props == ()
        assert dataclasses.replace(cluttered, props=()) == plain
        assert cluttered.props == make_street_scene(seed, props=True).props  # seeded
        assert {p.kind for p in cluttered.props} <= set(PROP_KINDS)
        assert sum(p.kind == "car" for p in cluttered.props) >= 5


def test_no_walker_walks_through_a_prop_and_no_camera_stands_in_one() -> None:
    for seed in range(12):
        scene = make_street_scene(seed, props=True, n_pedestrians=40)
        period = scene.street.length_m
        for prop in scene.props:
            fp = _footprint(prop)
            assert not any(_overlaps(fp, _lane_footprint(p), period) for p in scene.pedestrians), prop
            assert all(_distance(fp, *c.position_m[:2], period) >= CAMERA_CLEARANCE_M for c in scene.cameras)
            if prop.kind == "car":  # in the parking lane, clear of the sidewalk
                assert abs(prop.x_m) + prop.width_m / 2 <= scene.street.road_half_width_m


def _prop_bounds_and_parts(seed: int, ego: str, times: np.ndarray):
    scene = make_street_scene(seed, props=True, width=320, height=180, n_pedestrians=0, ego=ego_preset(ego))
    for cam in range(5):
        r = Renderer(scene, cam)
        parts = r.actor_parts(times)
        boxes = r.actor_bounds(times, np.zeros(times.size), np.ones((r.n_actors, times.size), np.bool_))
        for i in range(times.size):
            for o in range(r.n_actors):
                yield boxes[o, i], parts[o, i]


def _extent(parts: np.ndarray) -> tuple[float, float, float, float] | None:
    """(ymin, ymax, xmin, xmax) of the live parts' render-space geometry, or None."""
    live = parts[:, A.Q_KIND] != A.PART_NONE
    if not live.any():
        return None
    g = A.Q_GEO
    x_lo, x_hi = [], []
    for p in np.flatnonzero(live):
        if parts[p, A.Q_KIND] == A.PART_QUAD:
            xs = parts[p, g : g + 2 * A.N_VERTS : 2]
            x_lo.append(xs.min())
            x_hi.append(xs.max())
        else:
            r = parts[p, g + 4]
            x_lo.append(min(parts[p, g], parts[p, g + 2]) - r)
            x_hi.append(max(parts[p, g], parts[p, g + 2]) + r)
    return parts[live, A.Q_YMIN].min(), parts[live, A.Q_YMAX].max(), min(x_lo), max(x_hi)


@pytest.mark.parametrize("ego", ["none", "vehicle", "drone"])
def test_prop_bounds_contain_every_part(ego: str) -> None:
    """The touched-line test is only as good as the bounds: every face and capsule of every prop lies inside
    them, for props in view, beside and behind the camera (a vehicle camera drives past parked cars)."""
    near = 0
    for box, parts in _prop_bounds_and_parts(4, ego, np.linspace(0.0, 12.0, 25)):
        ext = _extent(parts)
        if box[0] > box[1]:
            assert ext is None
            continue
        if ext is None:
            continue
        assert np.isfinite(box).all()
        assert box[0] <= ext[0] + 1e-6 and ext[1] <= box[1] + 1e-6
        assert box[2] <= ext[2] + 1e-6 and ext[3] <= box[3] + 1e-6
        near += bool((parts[:, A.Q_KIND] != A.PART_NONE).any() and parts[:, A.Q_DEPTH].min() < 1.0)
    if ego == "vehicle":
        assert near > 0  # parts near the camera plane occur


def test_faces_crossing_the_near_plane_are_clipped_finite_polygons() -> None:
    """Cameras brushing past a parked car: faces cut by the near plane keep finite corners, five where the plane
    cuts a corner off."""
    scene = make_street_scene(4, props=True, width=320, height=180, n_pedestrians=0)
    car = next(p for p in scene.props if p.kind == "car")
    side = car.x_m + np.sign(-car.x_m) * (car.width_m / 2 + 0.03)  # just off its road-side flank
    most = 0
    for dy in np.linspace(-car.length_m / 2, car.length_m / 2, 7):
        for yaw, pitch in ((-60.0, -30.0), (60.0, -30.0), (-80.0, 25.0), (80.0, 25.0)):
            cam = Camera("beside", 320, 180, 35.0, 36.0, (side, car.y_m + dy, 0.8), yaw_deg=yaw, pitch_deg=pitch)
            parts = Renderer(scene, cam).actor_parts(np.zeros(1))[:, 0]
            quads = parts[parts[:, :, A.Q_KIND] == A.PART_QUAD]
            assert np.isfinite(quads).all()
            corners = quads[:, A.Q_GEO : A.Q_GEO + 2 * A.N_VERTS].reshape(-1, A.N_VERTS, 2)
            most = max([most, *(len({tuple(v) for v in q}) for q in corners)])
    assert most == 5


@pytest.mark.parametrize(("ego", "camera"), [("none", 1), ("none", 4), ("vehicle", 0), ("drone", 2)])
def test_rs_with_props_equals_brute_force(ego: str, camera: int) -> None:
    scene = make_street_scene(6, speed="fast", width=96, height=54, n_pedestrians=16, ego=ego_preset(ego),
                              props=True)
    r = Renderer(scene, camera)
    for t0 in (0, 1_500_000_000):
        times = _rs_times(54, t0)
        fast, ref = r.render_lines(times), r.reference_lines(times)
        assert np.abs(fast.image.astype(int) - ref.image.astype(int)).max() <= 1
        assert fast.truth.boxes() == ref.truth.boxes()
        np.testing.assert_array_equal(fast.truth.visible, ref.truth.visible)


def _walker_and_car(walker_y: float, walker_x: float, car: bool) -> tuple[Renderer, int]:
    """A still walker seen from a low camera, with or without a car parked on the line of sight at y = -4."""
    base = make_street_scene(0, width=480, height=270, n_pedestrians=1)
    p = base.pedestrians[0]
    walker = dataclasses.replace(p, lane_x_m=walker_x, lane_y_center_m=walker_y, lane_half_length_m=0.01,
                                 start_offset_m=0.0, speed_mps=0.0, height_m=1.75, build=1.0)
    props = (Prop("car", 4.0, -4.0, 4.5, 1.8, 1.5, (0.7, 0.1, 0.1), (0.03, 0.03, 0.04), 1),) if car else ()
    cam = Camera("low", 480, 270, 35.0, 36.0, (0.0, -20.0, 1.2), yaw_deg=14.0)
    scene = dataclasses.replace(base, pedestrians=(walker,), props=props)
    return Renderer(scene, cam), 0


def test_a_parked_car_hides_the_walker_behind_it_and_not_the_one_in_front() -> None:
    times = np.zeros(270, np.int64)
    behind = {car: _walker_and_car(0.0, 5.0, car) for car in (False, True)}
    vis = {car: r.render_lines(times).truth.visible_fraction()[o] for car, (r, o) in behind.items()}
    assert vis[False] > 0.95 and vis[True] < 0.35  # only the head shows over the roof
    r, o = _walker_and_car(-10.0, 2.5, True)  # between the camera and the car
    assert r.render_lines(times).truth.visible_fraction()[o] > 0.95


def test_props_are_scenery_not_objects() -> None:
    """No truth record, mask id or amodal mask is a prop's, and a prop's class is never 'person'."""
    scene = make_street_scene(2, props=True, width=320, height=180)
    tables = compile_scene(scene)
    n_walkers = len(scene.pedestrians)
    assert tables.actor_labelled == (True,) * n_walkers + (False,) * (len(tables.actor_ids) - n_walkers)
    assert "person" not in tables.actor_classes[n_walkers:]
    assert len(set(tables.actor_ids[:n_walkers]) & set(tables.actor_ids[n_walkers:])) == 0
    seen_props = 0
    for cam in range(5):
        r = Renderer(scene, cam)
        times = np.full(180, 10**9, np.int64)
        res = r.render_lines(times)
        seen_props += sum(b is not None for b in res.truth.boxes()[n_walkers:])
        objects = r.object_truth(res.truth, 10**9)
        assert {o.cls for o in objects} <= {"person"}
        assert {o.id for o in objects} <= {p.id for p in scene.pedestrians}
        owner, amodal = render_masks(r, times)
        assert set(np.unique(owner)) <= {0, *(p.id for p in scene.pedestrians)}
        assert set(amodal) <= {p.id for p in scene.pedestrians}
    assert seen_props > 0

