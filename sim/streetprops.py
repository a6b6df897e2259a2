"""Seeded street clutter: cars parked along the curbs, and trees, lamp poles, signs, benches and bins beside them.

``street_props(seed, street, pedestrians, cameras)`` draws from its own child generator of the scene seed
(``PROPS_STREAM``), so turning props on leaves a seed's street, walkers and cameras exactly as they were. Props
stand between the road and the walkers: cars in the parking lane along each curb, the rest on the curb strip
and the sidewalk's edge. None is placed where a walker's lane passes (its body's reach over the whole lane,
walkers in the road included), within ``CAMERA_CLEARANCE_M`` of a camera, on another prop, or (cars) on the
crosswalk, so no walker ever walks through a prop and no camera stands inside one.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .scene import Camera, Pedestrian, Prop, Street

PROPS_STREAM = 0x70726F70
"""Second word of the props' generator seed (``default_rng([seed, PROPS_STREAM])``): their own stream."""
CAMERA_CLEARANCE_M = 3.0
"""No prop's footprint comes closer than this (horizontally) to a scene camera."""
WALKER_REACH = 0.25
"""A walker's sideways reach, fraction of height x build (the renderer's bounds use the same margin)."""
PARKED_SHARE = 0.4
"""Share of the parking lane's car-length places that hold a parked car."""
FURNITURE_GAP_M = (7.0, 16.0)
"""Spacing of the curb-side furniture along each side, m (uniform)."""
FURNITURE = (("tree", 0.45), ("pole", 0.2), ("sign", 0.1), ("bench", 0.1), ("bin", 0.15))
"""Curb-side furniture kinds and their shares."""

_PAINT = np.array([(0.72, 0.72, 0.70), (0.42, 0.43, 0.45), (0.18, 0.18, 0.19), (0.03, 0.03, 0.035),
                   (0.45, 0.05, 0.04), (0.05, 0.10, 0.35), (0.03, 0.05, 0.15), (0.10, 0.20, 0.10),
                   (0.50, 0.42, 0.30)])
_PAINT_P = np.array([0.22, 0.2, 0.14, 0.16, 0.08, 0.08, 0.05, 0.03, 0.04])
_GLASS = (0.03, 0.035, 0.045)
_PLATES = ((0.50, 0.04, 0.03), (0.03, 0.12, 0.45), (0.65, 0.50, 0.05), (0.70, 0.70, 0.68))
_BENCH = ((0.30, 0.18, 0.09), (0.05, 0.15, 0.07), (0.25, 0.25, 0.26))
_BIN = ((0.04, 0.10, 0.05), (0.12, 0.12, 0.13), (0.03, 0.03, 0.03))

Footprint = tuple[float, float, float, float]  # x0, x1, y0, y1


def street_props(seed: int, street: Street, pedestrians: Sequence[Pedestrian],
                 cameras: Sequence[Camera]) -> tuple[Prop, ...]:
    """The street's props for scene seed ``seed`` (see the module docstring); the same inputs, the same props."""
    rng = np.random.default_rng([int(seed), PROPS_STREAM])
    blocked = [_lane_footprint(p) for p in pedestrians]
    period = street.length_m
    placed: list[Footprint] = []
    out: list[Prop] = []

    def free(fp: Footprint, gap: float = 0.3) -> bool:
        x0, x1, y0, y1 = fp
        if any(_overlaps(fp, b, period) for b in blocked):
            return False
        if any(_overlaps((x0 - gap, x1 + gap, y0 - gap, y1 + gap), q, period) for q in placed):
            return False
        return all(_distance(fp, c.position_m[0], c.position_m[1], period) >= CAMERA_CLEARANCE_M for c in cameras)

    half = street.length_m / 2
    for side in (-1, 1):
        y = -half + float(rng.uniform(0.0, 6.0))
        while y < half - 5.0:
            car = _car(rng, street, side, y)
            y += car.length_m + float(rng.uniform(0.8, 2.5))
            fp = _footprint(car)
            if rng.random() < PARKED_SHARE and abs(car.y_m - street.crosswalk_y_m) > 4.0 + car.length_m / 2 \
                    and free(fp):
                placed.append(fp)
                out.append(car)
        y = -half + float(rng.uniform(0.0, FURNITURE_GAP_M[1]))
        kinds, shares = zip(*FURNITURE, strict=True)
        while y < half:
            kind = str(rng.choice(kinds, p=shares))
            prop = _furniture(rng, kind, street, side, y)
            y += float(rng.uniform(*FURNITURE_GAP_M))
            fp = _footprint(prop)
            if free(fp):
                placed.append(fp)
                out.append(prop)
    return tuple(out)


def _car(rng: np.random.Generator, street: Street, side: int, y0: float) -> Prop:
    """A car parked 0.2 m off the curb on ``side``, its back end at ``y0``, facing the traffic's way."""
    length, width = float(rng.uniform(3.8, 4.9)), float(rng.uniform(1.7, 1.9))
    paint = _PAINT[rng.choice(len(_PAINT), p=_PAINT_P)] * rng.uniform(0.85, 1.15)
    return Prop("car", side * (street.road_half_width_m - 0.2 - width / 2), y0 + length / 2, length, width,
                float(rng.uniform(1.4, 1.6)), _rgb(paint), _GLASS, side)


def _furniture(rng: np.random.Generator, kind: str, street: Street, side: int, y: float) -> Prop:
    """One piece of curb-side furniture of ``kind`` at ``y`` on ``side``."""
    curb = street.road_half_width_m + street.curb_width_m / 2
    if kind == "tree":
        crown = float(rng.uniform(2.6, 4.4))
        height = max(float(rng.uniform(5.0, 9.0)), 2.5 + crown)  # the crown starts above the tallest walker
        bark = np.array((0.12, 0.08, 0.05)) * rng.uniform(0.7, 1.3)
        leaves = (rng.uniform(0.04, 0.12), rng.uniform(0.12, 0.25), rng.uniform(0.03, 0.08))
        return Prop("tree", side * curb, y, crown, crown, height, _rgb(bark), _rgb(leaves), 1)
    if kind == "pole":
        return Prop("pole", side * curb, y, 0.14, 0.14, float(rng.uniform(5.5, 7.5)), (0.08, 0.08, 0.09),
                    (0.55, 0.55, 0.52), -side)  # the lamp's arm reaches over the road
    if kind == "sign":
        plate = float(rng.uniform(0.5, 0.75))
        height = max(float(rng.uniform(2.5, 2.9)), 2.15 + plate)  # the plate hangs above the walkers' heads
        return Prop("sign", side * curb, y, 0.2, plate, height, (0.35, 0.35, 0.36),
                    _PLATES[int(rng.integers(len(_PLATES)))], 1 if rng.random() < 0.5 else -1)
    edge = street.road_half_width_m + street.curb_width_m
    if kind == "bench":
        depth = 0.55
        return Prop("bench", side * (edge + 0.05 + depth / 2), y, float(rng.uniform(1.5, 2.0)), depth, 0.85,
                    _BENCH[int(rng.integers(len(_BENCH)))], (0.05, 0.05, 0.05), side)  # its back to the road
    radius = float(rng.uniform(0.22, 0.3))
    return Prop("bin", side * (edge + radius + 0.05), y, 2 * radius, 2 * radius, float(rng.uniform(0.8, 1.0)),
                _BIN[int(rng.integers(len(_BIN)))], (0.0, 0.0, 0.0), 1)


def _footprint(prop: Prop) -> Footprint:
    """Where a prop stands at walkers' heights: its trunk or pole for trees, poles and signs, else its box."""
    if prop.kind in ("tree", "pole", "sign"):
        r = 0.25 if prop.kind == "tree" else 0.1
        return (prop.x_m - r, prop.x_m + r, prop.y_m - r, prop.y_m + r)
    return (prop.x_m - prop.width_m / 2, prop.x_m + prop.width_m / 2, prop.y_m - prop.length_m / 2,
            prop.y_m + prop.length_m / 2)


def _lane_footprint(p: Pedestrian) -> Footprint:
    """The ground a walker's body can cover over its whole lane (turns included)."""
    reach = WALKER_REACH * p.height_m * max(p.build, 1.0)
    along = p.lane_half_length_m + 0.4 * p.height_m
    return (p.lane_x_m - reach, p.lane_x_m + reach, p.lane_y_center_m - along, p.lane_y_center_m + along)


def _overlaps(a: Footprint, b: Footprint, period: float) -> bool:
    """Whether two footprints overlap on the street, which repeats every ``period`` along Y."""
    if a[1] <= b[0] or b[1] <= a[0]:
        return False
    return any(a[2] + k * period < b[3] and b[2] < a[3] + k * period for k in (-1, 0, 1))


def _distance(fp: Footprint, x: float, y: float, period: float) -> float:
    """Horizontal distance from (x, y) to a footprint, the street repeating every ``period`` along Y."""
    dx = max(fp[0] - x, 0.0, x - fp[1])
    dy = min(max(fp[2] + k * period - y, 0.0, y - fp[3] - k * period) for k in (-1, 0, 1))
    return float(np.hypot(dx, dy))


def _rgb(v: Sequence[float]) -> tuple[float, float, float]:
    return (float(np.clip(v[0], 0.0, 0.9)), float(np.clip(v[1], 0.0, 0.9)), float(np.clip(v[2], 0.0, 0.9)))
