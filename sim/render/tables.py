"""Scene data to the flat float64 tables the render kernels read (layouts in ``world`` and ``body``)."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from ..scene import BAGS, FACADES, Camera, Lighting, Prop, Scene
from . import body as B
from . import props as Pr
from . import world as Wd

BUILDING_BIN_M = 0.5
PROP_ID_BASE = 1_000_000
"""Props' actor ids start here (walkers and bars count from 1), so no prop shares an id with an object."""
CAR_SLICE_M = 1.2
"""Longest slice of a parked car: each is its own actor row, drawn at its own depth (see ``props``)."""


@dataclass(frozen=True)
class CompiledScene:
    """The kernel tables of one scene: world, building lookup, lighting and actors.

    ``building_lut`` (2 sides x (bins + 1), int64) gives the row of ``buildings`` standing in each street bin;
    its last entry on each side and its empty bins name the table's last row, a sentinel no ray hits and no
    shadow comes from (``world.NO_BUILDING_HEIGHT``), so the C shader reads no table under a condition.
    """

    world: np.ndarray
    building_lut: np.ndarray
    buildings: np.ndarray
    light: np.ndarray
    actors: np.ndarray
    actor_ids: tuple[int, ...]
    actor_classes: tuple[str, ...]
    actor_speeds_mps: tuple[float, ...]
    actor_labelled: tuple[bool, ...]  # False for scenery (props): drawn and hiding others, but no truth record


def compile_camera(cam: Camera, transposed: bool = False) -> np.ndarray:
    """Camera table of one camera; ``transposed`` renders image columns as lines (column readout)."""
    t = np.zeros(Wd.CAM_COLS)
    fx = cam.fx_px
    t[Wd.C_FX], t[Wd.C_FY] = fx, fx
    t[Wd.C_CX], t[Wd.C_CY] = cam.width / 2.0, cam.height / 2.0
    t[Wd.C_W], t[Wd.C_H] = cam.width, cam.height
    t[Wd.C_TRANSPOSED] = 1.0 if transposed else 0.0
    t[Wd.C_POS : Wd.C_POS + 3] = cam.position_m
    t[Wd.C_YAW], t[Wd.C_PITCH], t[Wd.C_ROLL] = (math.radians(v) for v in (cam.yaw_deg, cam.pitch_deg, cam.roll_deg))
    ego = cam.ego
    t[Wd.C_VEL : Wd.C_VEL + 3] = ego.velocity_mps
    t[Wd.C_PAN], t[Wd.C_TILT], t[Wd.C_ROLLRATE] = (math.radians(v) for v in (ego.pan_dps, ego.tilt_dps, ego.roll_dps))
    t[Wd.C_VIB_ANG] = math.radians(ego.vibration_deg)
    t[Wd.C_VIB_POS], t[Wd.C_VIB_HZ] = ego.vibration_m, ego.vibration_hz
    t[Wd.C_MOVING] = 1.0 if ego.moving else 0.0
    return t


def compile_scene(scene: Scene) -> CompiledScene:
    """Flatten a Scene into kernel tables."""
    world = np.zeros(Wd.WORLD_COLS)
    world[Wd.W_BIN] = BUILDING_BIN_M
    world[Wd.W_YHALF] = 1.0
    world[Wd.W_SEED] = scene.seed & 0x7FFFFFFF
    light = _compile_light(scene)
    buildings = np.zeros((0, Wd.BLD_COLS))
    lut = -np.ones((2, 0), np.int64)
    if scene.kind == "street" and scene.street is not None:
        st = scene.street
        world[Wd.W_KIND] = Wd.KIND_STREET
        world[Wd.W_ROAD], world[Wd.W_CURB] = st.road_half_width_m, st.curb_width_m
        world[Wd.W_WALK] = st.sidewalk_width_m
        world[Wd.W_FACADE] = st.facade_x_m
        world[Wd.W_YHALF] = st.length_m / 2.0
        world[Wd.W_ASPHALT : Wd.W_ASPHALT + 3] = st.asphalt_color
        world[Wd.W_SIDEWALK : Wd.W_SIDEWALK + 3] = st.sidewalk_color
        world[Wd.W_CROSS] = st.crosswalk_y_m
        world[Wd.W_SEED] = st.texture_seed & 0x7FFFFFFF
        buildings, lut = _compile_buildings(st.buildings, st.length_m)
    elif scene.kind == "chart" and scene.chart is not None:
        world[Wd.W_KIND] = Wd.KIND_CHART
        world[Wd.W_ASPHALT : Wd.W_ASPHALT + 3] = scene.chart.board_rgb
    else:
        world[Wd.W_KIND] = Wd.KIND_FLAT
        world[Wd.W_LEVEL] = scene.flat_level
    actors, ids, classes, speeds = _compile_actors(scene)
    labelled = (True,) * len(ids)
    if scene.props:
        props = [_prop_rows(prop, PROP_ID_BASE + i) for i, prop in enumerate(scene.props)]
        rows = [row for rs in props for row in rs]
        actors = np.concatenate([actors, np.array(rows)])
        ids += tuple(PROP_ID_BASE + i for i, rs in enumerate(props) for _ in rs)
        classes += tuple(prop.kind for prop, rs in zip(scene.props, props, strict=True) for _ in rs)
        speeds += (0.0,) * len(rows)
        labelled += (False,) * len(rows)
    lut, buildings = _with_sentinel(lut, buildings)
    return CompiledScene(world, lut, buildings, light, actors, ids, classes, speeds, labelled)


def _with_sentinel(lut: np.ndarray, buildings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The lookup (-1: no building) and table in the shader's layout: a sentinel row named by every empty bin
    and by one more bin past the end on each side."""
    n_bld = buildings.shape[0]
    sentinel = np.zeros((1, Wd.BLD_COLS))
    sentinel[0, Wd.B_HEIGHT] = Wd.NO_BUILDING_HEIGHT
    padded = np.concatenate([np.where(lut < 0, n_bld, lut), np.full((2, 1), n_bld)], axis=1)
    return np.ascontiguousarray(padded, np.int64), np.ascontiguousarray(np.concatenate([buildings, sentinel]))


def _compile_light(scene: Scene) -> np.ndarray:
    li = scene.lighting
    t = np.zeros(Wd.LIGHT_COLS)
    t[Wd.L_SUN : Wd.L_SUN + 3] = li.sun_direction
    t[Wd.L_SUN_RGB : Wd.L_SUN_RGB + 3] = li.sun_rgb
    t[Wd.L_AMB : Wd.L_AMB + 3] = li.ambient_rgb
    t[Wd.L_HORIZON : Wd.L_HORIZON + 3] = li.sky_horizon_rgb
    t[Wd.L_ZENITH : Wd.L_ZENITH + 3] = li.sky_zenith_rgb
    t[Wd.L_HAZE : Wd.L_HAZE + 3] = li.haze_rgb
    t[Wd.L_FOG] = li.fog_distance_m
    t[Wd.L_GLOW] = li.window_glow
    return t


def _compile_buildings(buildings, length_m: float) -> tuple[np.ndarray, np.ndarray]:
    n_bins = int(math.ceil(length_m / BUILDING_BIN_M))
    lut = -np.ones((2, n_bins), np.int64)
    tab = np.zeros((len(buildings), Wd.BLD_COLS))
    half = length_m / 2.0
    for i, b in enumerate(buildings):
        row = tab[i]
        row[Wd.B_SIDE], row[Wd.B_Y0], row[Wd.B_Y1], row[Wd.B_HEIGHT] = b.side, b.y0_m, b.y1_m, b.height_m
        row[Wd.B_RGB : Wd.B_RGB + 3] = b.color
        row[Wd.B_WIN_RGB : Wd.B_WIN_RGB + 3] = b.window_color
        row[Wd.B_FLOOR], row[Wd.B_WIN_W], row[Wd.B_WIN_SP] = b.floor_height_m, b.window_width_m, b.window_spacing_m
        row[Wd.B_LIT] = b.lit_fraction
        row[Wd.B_MAT] = FACADES.index(b.material)  # FACADES is in the shader's MAT_* order
        lo = max(int(math.floor((b.y0_m + half) / BUILDING_BIN_M)), 0)
        hi = min(int(math.ceil((b.y1_m + half) / BUILDING_BIN_M)), n_bins)
        lut[0 if b.side < 0 else 1, lo:hi] = i
    return tab, lut


CAST_MIN_ELEVATION_DEG = 15.0
"""Below this sun elevation walkers cast no sun shadow (it would reach past their bounds: 3.7 x their height)."""


def _cast_shadow(lighting: Lighting) -> tuple[float, float, tuple[float, float, float]]:
    """A walker's sun shadow under ``lighting``: where it ends on the ground per metre of the walker's height
    (x, y), and the share of the ground's light it takes per channel (the sun's, over sun and sky); none when
    the sun is lower than CAST_MIN_ELEVATION_DEG."""
    sx, sy, sz = lighting.sun_direction
    if lighting.sun_elevation_deg < CAST_MIN_ELEVATION_DEG or max(lighting.sun_rgb) <= 0.0:
        return 0.0, 0.0, (0.0, 0.0, 0.0)
    share = tuple(float(s * sz / (s * sz + a)) if s * sz + a > 0 else 0.0
                  for s, a in zip(lighting.sun_rgb, lighting.ambient_rgb, strict=True))
    return -sx / sz, -sy / sz, (share[0], share[1], share[2])


def _compile_actors(scene: Scene) -> tuple[np.ndarray, tuple[int, ...], tuple[str, ...], tuple[float, ...]]:
    rows, ids, classes, speeds = [], [], [], []
    cast = _cast_shadow(scene.lighting)
    for p in scene.pedestrians:
        a = np.zeros(B.ACTOR_COLS)
        a[B.A_TYPE] = B.TYPE_PEDESTRIAN
        a[B.A_STATIC] = 1.0 if p.speed_mps == 0.0 else 0.0
        a[B.A_SPEED], a[B.A_ID] = p.speed_mps, p.id
        a[B.P_LANE_X], a[B.P_YC], a[B.P_HALF] = p.lane_x_m, p.lane_y_center_m, p.lane_half_length_m
        a[B.P_OFF], a[B.P_SPEED], a[B.P_H], a[B.P_BUILD] = p.start_offset_m, p.speed_mps, p.height_m, p.build
        a[B.P_PHASE], a[B.P_DIR] = p.gait_phase, float(p.direction)
        a[B.P_LONG_HAIR], a[B.P_SLEEVES] = float(p.long_hair), float(p.long_sleeves)
        a[B.P_STRIDE] = p.stride_length_m
        a[B.P_BAG_KIND] = BAGS.index(p.bag)  # BAGS is in B.BAG_* order
        a[B.P_BAG : B.P_BAG + 3] = p.bag_rgb
        a[B.P_SKIRT] = float(p.skirt)
        a[B.P_SHADOW] = scene.contact_shadow
        if scene.contact_shadow > 0.0:
            a[B.P_CAST_X], a[B.P_CAST_Y], a[B.P_CAST_S : B.P_CAST_S + 3] = cast
        for off, rgb in ((B.P_SKIN, p.skin), (B.P_HAIR, p.hair), (B.P_SHIRT, p.shirt), (B.P_PANTS, p.pants),
                         (B.P_SHOES, p.shoes)):
            a[off : off + 3] = rgb
        rows.append(a)
        ids.append(p.id)
        classes.append(p.cls)
        speeds.append(p.speed_mps)
    if scene.chart is not None:
        ch = scene.chart
        period = ch.pitch_px * len(ch.bars)
        for bar in ch.bars:
            a = np.zeros(B.ACTOR_COLS)
            a[B.A_TYPE] = B.TYPE_BAR
            a[B.A_STATIC] = 1.0 if ch.vx_px_s == 0.0 else 0.0
            a[B.A_ID] = bar.id
            a[B.R_X0], a[B.R_WIDTH], a[B.R_VX], a[B.R_PERIOD] = bar.x0_px, bar.width_px, ch.vx_px_s, period
            a[B.R_RGB : B.R_RGB + 3] = bar.color
            rows.append(a)
            ids.append(bar.id)
            classes.append("bar")
            speeds.append(0.0)  # image-plane target: no world speed
    actors = np.array(rows) if rows else np.zeros((0, B.ACTOR_COLS))
    return actors, tuple(ids), tuple(classes), tuple(speeds)


def _prop_rows(prop: Prop, actor_id: int) -> list[np.ndarray]:
    """The actor rows of one prop (``props``' columns): one, or a parked car's slices."""
    a = np.zeros(B.ACTOR_COLS)
    a[B.A_TYPE], a[B.A_STATIC], a[B.A_SPEED], a[B.A_ID] = B.TYPE_PROP, 1.0, 0.0, actor_id
    a[Pr.G_KIND] = Pr.PROP_CODES[prop.kind]
    a[Pr.G_X], a[Pr.G_Y] = prop.x_m, prop.y_m
    a[Pr.G_L], a[Pr.G_W], a[Pr.G_H], a[Pr.G_DIR] = prop.length_m, prop.width_m, prop.height_m, float(prop.facing)
    a[Pr.G_RGB : Pr.G_RGB + 3] = prop.color
    a[Pr.G_RGB2 : Pr.G_RGB2 + 3] = prop.color2
    length, h = prop.length_m, prop.height_m
    if prop.kind == "car":
        # Body to 62 % of the height; the cabin over the middle, nearer the back (a bonnet longer than the boot).
        lo, hi = (-0.30 * length, 0.25 * length) if prop.facing > 0 else (-0.25 * length, 0.30 * length)
        a[Pr.G_A], a[Pr.G_B], a[Pr.G_C] = 0.62 * h, lo, hi
        n = max(1, math.ceil(length / CAR_SLICE_M))
        cuts = np.linspace(-length / 2, length / 2, n + 1)
        rows = []
        for s0, s1 in itertools.pairwise(cuts):
            row = a.copy()
            row[Pr.G_S0], row[Pr.G_S1] = s0, s1
            rows.append(row)
        return rows
    if prop.kind == "tree":
        crown = prop.width_m / 2
        a[Pr.G_A], a[Pr.G_B], a[Pr.G_C] = 0.05 + 0.02 * h, h - 1.8 * crown, crown
        a[Pr.G_DIR] = (prop.x_m * 7.1 + prop.y_m * 3.7) % (2 * math.pi)  # the crown's turn, radians
    elif prop.kind == "pole":
        a[Pr.G_A], a[Pr.G_B] = 0.07, 1.2  # pole radius, lamp arm
    elif prop.kind == "sign":
        a[Pr.G_A] = prop.width_m  # plate size
    elif prop.kind == "bench":
        a[Pr.G_A] = 0.45  # seat height
    else:
        a[Pr.G_A] = prop.width_m / 2  # bin radius
    return [a]
