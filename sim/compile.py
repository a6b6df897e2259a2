"""Scene data to the flat float64 tables the render kernels read (layouts in ``rollcam.sim._world`` and ``._body``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import _body as B
from . import _world as Wd
from .scene import Camera, Scene

BUILDING_BIN_M = 0.5


@dataclass(frozen=True)
class CompiledScene:
    """The kernel tables of one scene: world, building lookup, lighting and actors.

    ``building_lut`` (2 sides x (bins + 1), int64) gives the row of ``buildings`` standing in each street bin;
    its last entry on each side and its empty bins name the table's last row, a sentinel no ray hits and no
    shadow comes from (``_world.NO_BUILDING_HEIGHT``), so the C shader reads no table under a condition.
    """

    world: np.ndarray
    building_lut: np.ndarray
    buildings: np.ndarray
    light: np.ndarray
    actors: np.ndarray
    actor_ids: tuple[int, ...]
    actor_classes: tuple[str, ...]
    actor_speeds_mps: tuple[float, ...]


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
    lut, buildings = _with_sentinel(lut, buildings)
    return CompiledScene(world, lut, buildings, light, actors, ids, classes, speeds)


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
        lo = max(int(math.floor((b.y0_m + half) / BUILDING_BIN_M)), 0)
        hi = min(int(math.ceil((b.y1_m + half) / BUILDING_BIN_M)), n_bins)
        lut[0 if b.side < 0 else 1, lo:hi] = i
    return tab, lut


def _compile_actors(scene: Scene) -> tuple[np.ndarray, tuple[int, ...], tuple[str, ...], tuple[float, ...]]:
    rows, ids, classes, speeds = [], [], [], []
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
