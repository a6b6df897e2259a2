"""Seeded procedural scenes: city streets with crowds (the study's setting), moving charts, flat fields, flicker.

``make_scene(kind, seed=..., **options)`` is the one entry point; the same seed always gives the same scene.
Every sampler draws from a ``numpy.random.Generator`` built from the seed here, never a global one.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError

from .flicker import LAMPS, Waveform
from .scene import (
    Building,
    Camera,
    Chart,
    ChartBar,
    EgoMotion,
    Lighting,
    ModulatedLight,
    Pedestrian,
    Scene,
    Street,
)
from .streetprops import street_props

# The study's virtual camera: 35 mm lens on a 16:9 digital filmback (36 x 20.25 mm), 1920x1080.
STUDY_FOCAL_MM = 35.0
STUDY_SENSOR_WIDTH_MM = 36.0

TIMES_OF_DAY: dict[str, Lighting] = {
    "dawn": Lighting("dawn", 80.0, 6.0, (0.55, 0.32, 0.20), (0.10, 0.09, 0.12), (0.55, 0.38, 0.32),
                     (0.16, 0.18, 0.30), (0.40, 0.32, 0.30), 260.0, 0.35),
    "morning": Lighting("morning", 110.0, 28.0, (0.95, 0.85, 0.70), (0.22, 0.24, 0.30), (0.62, 0.70, 0.80),
                        (0.25, 0.40, 0.70), (0.60, 0.65, 0.72), 380.0, 0.0),
    "noon": Lighting("noon", 170.0, 62.0, (1.10, 1.05, 0.98), (0.28, 0.30, 0.35), (0.70, 0.78, 0.88),
                     (0.28, 0.45, 0.80), (0.70, 0.74, 0.80), 450.0, 0.0),
    "afternoon": Lighting("afternoon", 235.0, 35.0, (1.00, 0.88, 0.72), (0.24, 0.25, 0.30),
                          (0.68, 0.70, 0.76), (0.26, 0.42, 0.74), (0.66, 0.66, 0.70), 400.0, 0.0),
    "dusk": Lighting("dusk", 285.0, 4.0, (0.45, 0.22, 0.10), (0.06, 0.06, 0.10), (0.45, 0.25, 0.22),
                     (0.08, 0.09, 0.20), (0.30, 0.20, 0.20), 240.0, 0.55),
    "night": Lighting("night", 285.0, -25.0, (0.0, 0.0, 0.0), (0.010, 0.010, 0.014), (0.030, 0.028, 0.040),
                      (0.004, 0.005, 0.012), (0.035, 0.030, 0.032), 200.0, 0.8),
}
DAYLIGHT = ("morning", "noon", "afternoon")
DATASET_TIMES = ("dawn", "morning", "noon", "afternoon", "dusk")
"""The times of day a dataset covers unless told otherwise (the study's five)."""
LAMP_TIMES = ("dusk", "night")
"""Times of day at which the street lamps and LED signs are on (``lamps='auto'``)."""

LAMP_TYPES = (*LAMPS, "led")
"""Street lamp types: the mains lamps of ``rollcam.sim.flicker.LAMPS``, or PWM-dimmed LEDs."""
_LAMP_RGB = {"incandescent": (1.0, 0.78, 0.52), "halogen": (1.0, 0.84, 0.64), "fluorescent": (0.86, 0.95, 1.0),
             "sodium": (1.0, 0.62, 0.22), "led": (0.95, 0.95, 1.0)}
# A lamp-lit street's light, relative to noon sun on white ~ 1: what a night exposure is set for.
_LAMP_AMBIENT, _LAMP_OVERHEAD = 0.05, 0.08

SPEED_PRESETS = {"static": 0.0, "normal": 1.0, "fast": 10.0}
"""Speed multipliers: 'normal' walkers go up to 2 m/s as in the study, 'fast' ten times that."""

# Linear albedos. Skin: measured reflectances run from ~(0.66, 0.49, 0.40) for very light to ~(0.2, 0.11, 0.07)
# for very dark skin; brighter values read as white plaster under the sun.
_SKIN = np.array([(0.62, 0.44, 0.35), (0.55, 0.38, 0.28), (0.45, 0.30, 0.20), (0.33, 0.20, 0.12),
                  (0.20, 0.11, 0.07), (0.66, 0.49, 0.40)])
_HAIR = np.array([(0.03, 0.025, 0.02), (0.12, 0.07, 0.04), (0.30, 0.18, 0.08), (0.55, 0.45, 0.25),
                  (0.45, 0.44, 0.42), (0.25, 0.08, 0.04)])
_SHOES = np.array([(0.03, 0.03, 0.03), (0.20, 0.12, 0.07), (0.65, 0.65, 0.65), (0.08, 0.08, 0.12)])


def parse_speed(speed: str | float) -> float:
    """Speed multiplier from 'static', 'normal', 'fast' or a number (1.0 = normal)."""
    if isinstance(speed, (int, float)):
        value = float(speed)
    elif str(speed).lower() in SPEED_PRESETS:
        return SPEED_PRESETS[str(speed).lower()]
    else:
        try:
            value = float(speed)
        except ValueError:
            raise ConfigError(
                f"speed {speed!r} is not one of {sorted(SPEED_PRESETS)} or a number (multiplier of normal)"
            ) from None
    if not math.isfinite(value) or value < 0:
        raise ConfigError(f"speed multiplier must be a finite number >= 0, got {speed!r}")
    return value


def _clothing(rng: np.random.Generator, denim_p: float = 0.0) -> tuple[float, float, float]:
    """A clothing colour (linear albedo): mostly muted, sometimes saturated, blue denim ``denim_p`` of the time.

    Brightness is log-uniform between dyed black (0.03) and white cotton (0.75), as fabrics are: many dark
    garments, some light ones, few exactly mid-grey.
    """
    if rng.random() < denim_p:
        v = math.exp(rng.uniform(math.log(0.12), math.log(0.4)))
        return (0.45 * v, 0.62 * v, v)
    hue = rng.uniform(0, 6)
    sat = rng.choice([0.1, 0.3, 0.6, 0.8], p=[0.35, 0.3, 0.2, 0.15])
    val = math.exp(rng.uniform(math.log(0.03), math.log(0.75)))
    c = val * (1 - sat)
    x = (1 - abs(hue % 2 - 1)) * val * sat
    i = int(hue)
    base = [(val, c + x, c), (c + x, val, c), (c, val, c + x), (c, c + x, val), (c + x, c, val), (val, c, c + x)][i]
    return (float(base[0]), float(base[1]), float(base[2]))


def make_pedestrian(rng: np.random.Generator, pid: int, lane_x_m: float, lane_y_center_m: float,
                    lane_half_length_m: float, speed_mps: float) -> Pedestrian:
    """One walker with random body, skin, hair and clothing on the given lane."""
    female = rng.random() < 0.5
    height = float(np.clip(rng.normal(1.64 if female else 1.77, 0.07), 1.45, 2.0))
    if rng.random() < 0.08:
        height = float(rng.uniform(1.05, 1.4))  # children
    return Pedestrian(
        id=pid,
        lane_x_m=lane_x_m,
        lane_y_center_m=lane_y_center_m,
        lane_half_length_m=lane_half_length_m,
        start_offset_m=float(rng.uniform(0, 4 * lane_half_length_m)),
        speed_mps=speed_mps,
        height_m=height,
        build=float(np.clip(rng.normal(0.95 if female else 1.05, 0.1), 0.8, 1.3)),
        skin=tuple(float(v) for v in _SKIN[rng.integers(len(_SKIN))]),
        hair=tuple(float(v) for v in _HAIR[rng.integers(len(_HAIR))]),
        shirt=_clothing(rng),
        pants=_clothing(rng, denim_p=0.3),
        shoes=tuple(float(v) for v in _SHOES[rng.integers(len(_SHOES))]),
        long_hair=bool(rng.random() < (0.6 if female else 0.1)),
        long_sleeves=bool(rng.random() < 0.6),
        gait_phase=float(rng.uniform(0, 2 * math.pi)),
        direction=1 if rng.random() < 0.5 else -1,
    )


CROWD_STREAM = 0xC0FFEE
"""Child stream of a street's seed for who stands and who walks together: drawn apart from the layout's own
generator, so a seed's buildings, cameras and walkers' lanes and clothes stay where they were."""
STANDING_P, COMPANION_P, COMPANION_GAP_M = 0.12, 0.2, (0.55, 0.75)
"""Share of walkers standing still (waiting, talking, looking at a phone), share walking beside the previous
walker, and the lateral gap between two walking together, m."""


OUTFIT_STREAM = 0xBA65
"""Child stream of a street's seed for what walkers carry and wear beyond shirt and trousers (bags, skirts): drawn
apart from the layout's own generator, so a seed's walkers stay who and where they were."""
BACKPACK_P, SHOULDER_BAG_P, SKIRT_P = 0.22, 0.15, 0.12
"""Share of walkers with a backpack, with a bag on a shoulder strap, and in a skirt (adults only, as the
children here are small adults)."""
_BAG_COLOURS = ((0.03, 0.03, 0.035), (0.05, 0.07, 0.12), (0.22, 0.12, 0.06), (0.12, 0.14, 0.10), (0.35, 0.05, 0.05),
                (0.30, 0.30, 0.32))
"""Bag albedos: black, navy and khaki nylon, brown leather, red, grey."""


def _pick(colours: tuple, r: float) -> tuple[float, ...]:
    """The entry of ``colours`` that a uniform draw ``r`` in [0, 1) selects."""
    return colours[min(int(r * len(colours)), len(colours) - 1)]


def _outfits(rng: np.random.Generator, peds: list[Pedestrian]) -> list[Pedestrian]:
    """Bags and skirts, each walker drawn independently (three draws each, so one's outfit moves no other's)."""
    out = []
    for p in peds:
        r_bag, r_colour, r_skirt = rng.random(3)
        bag = "backpack" if r_bag < BACKPACK_P else "shoulder" if r_bag < BACKPACK_P + SHOULDER_BAG_P else "none"
        colour = _pick(_BAG_COLOURS, r_colour)
        out.append(replace(p, bag=bag, bag_rgb=colour, skirt=bool(r_skirt < SKIRT_P and p.height_m >= 1.45)))
    return out


FACADE_STREAM = 0xFACADE
"""Child stream of a street's seed for what each facade is built of: drawn apart from the layout's own generator,
so a seed's buildings keep their extents, heights and window grids."""
BRICK_P, STONE_P, GLASS_P, GLASS_MIN_HEIGHT_M = 0.30, 0.15, 0.12, 15.0
"""Share of facades in brick, in ashlar stone, and in glass curtain wall (of those at least the given height)."""
_BRICK_COLOURS = ((0.38, 0.16, 0.10), (0.30, 0.17, 0.12), (0.50, 0.40, 0.27), (0.22, 0.12, 0.09))
"""Brick albedos: red, brown, buff and dark engineering brick."""
_STONE_COLOURS = ((0.52, 0.47, 0.39), (0.45, 0.44, 0.42), (0.60, 0.56, 0.48))
"""Stone albedos: sandstone, granite, limestone."""
_PANE_COLOURS = ((0.05, 0.08, 0.10), (0.04, 0.07, 0.06), (0.09, 0.07, 0.05), (0.06, 0.06, 0.07))
"""Curtain-wall pane albedos (what is behind the glass, tinted): blue, green, bronze, grey."""


def _facades(rng: np.random.Generator, buildings: tuple[Building, ...]) -> tuple[Building, ...]:
    """Each facade's material and its colours (four draws per building, so one's moves no other's)."""
    out = []
    for b in buildings:
        r_mat, r_colour, r_shade, r_frame = rng.random(4)
        shade = 0.85 + 0.3 * r_shade
        if r_mat < BRICK_P:
            b = replace(b, material="brick", color=tuple(v * shade for v in _pick(_BRICK_COLOURS, r_colour)))
        elif r_mat < BRICK_P + STONE_P:
            b = replace(b, material="stone", color=tuple(v * shade for v in _pick(_STONE_COLOURS, r_colour)))
        elif r_mat < BRICK_P + STONE_P + GLASS_P and b.height_m >= GLASS_MIN_HEIGHT_M:
            mullion = 0.08 + 0.2 * r_frame
            b = replace(b, material="glass", color=(mullion, mullion, mullion * 1.04),
                        window_color=tuple(v * shade for v in _pick(_PANE_COLOURS, r_colour)))
        out.append(b)
    return tuple(out)


def _crowd_behaviour(rng: np.random.Generator, peds: list[Pedestrian], walk_lo: float, walk_hi: float
                     ) -> list[Pedestrian]:
    """A street crowd is not all lone walkers: some stand still and some walk in pairs, side by side."""
    out: list[Pedestrian] = []
    for i, p in enumerate(peds):
        r = rng.random()
        gap = float(rng.uniform(*COMPANION_GAP_M))
        prev = out[i - 1] if i else None
        if r < STANDING_P:
            p = replace(p, speed_mps=0.0)
        elif (r < STANDING_P + COMPANION_P and prev is not None and prev.speed_mps > 0.0
              and abs(prev.lane_x_m) >= walk_lo):
            # beside the previous walker, towards the roomier side of the sidewalk; same pace and direction
            side = 1.0 if abs(prev.lane_x_m) + gap <= walk_hi else -1.0
            lane_x = math.copysign(abs(prev.lane_x_m) + side * gap, prev.lane_x_m)
            p = replace(p, lane_x_m=lane_x, lane_y_center_m=prev.lane_y_center_m,
                        lane_half_length_m=prev.lane_half_length_m, start_offset_m=prev.start_offset_m,
                        speed_mps=prev.speed_mps, direction=prev.direction)
        out.append(p)
    return out


def _buildings(rng: np.random.Generator, length_m: float) -> tuple[Building, ...]:
    out = []
    for side in (-1, 1):
        y = -length_m / 2
        while y < length_m / 2:
            w = float(rng.uniform(8, 26))
            base = rng.uniform(0.15, 0.55)
            tint = rng.normal(0, 0.06, 3)
            color = tuple(float(np.clip(base + t, 0.05, 0.8)) for t in tint)
            glass = tuple(float(v) for v in np.clip(rng.uniform(0.04, 0.12) + rng.normal(0, 0.02, 3), 0.02, 0.3))
            out.append(Building(
                side=side, y0_m=y, y1_m=min(y + w, length_m / 2), height_m=float(rng.uniform(9, 45)),
                color=color, window_color=glass, floor_height_m=float(rng.uniform(3.0, 3.8)),
                window_width_m=float(rng.uniform(0.9, 1.6)), window_spacing_m=float(rng.uniform(2.2, 3.4)),
                lit_fraction=float(rng.uniform(0.1, 0.5)),
            ))
            y += w
    return tuple(out)


def _street_cameras(rng: np.random.Generator, street: Street, n: int, width: int, height: int,
                    focal_mm: float, sensor_width_mm: float, ego: EgoMotion) -> tuple[Camera, ...]:
    """``n`` cameras around the crowd: along the street, across it, high and low (the study used five)."""
    cams = []
    walk_x = street.road_half_width_m + street.curb_width_m + street.sidewalk_width_m / 2
    presets = [  # (x, y, z, yaw, pitch): looking across, along, diagonally, from above
        (0.0, -26.0, 3.5, 0.0, -6.0),
        (walk_x - 0.3, -14.0, 2.2, -25.0, -5.0),
        (-walk_x + 0.5, -2.0, 1.6, 75.0, -4.0),
        (-street.facade_x_m + 0.8, 6.0, 6.5, 120.0, -16.0),
        (walk_x, 22.0, 1.4, 195.0, -3.0),
    ]
    for i in range(n):
        x, y, z, yaw, pitch = presets[i % len(presets)]
        jitter = rng.normal(0, 1, 5) * (0.4, 1.0, 0.2, 4.0, 1.0)
        cams.append(Camera(
            name=f"cam{i}", width=width, height=height, focal_mm=focal_mm, sensor_width_mm=sensor_width_mm,
            position_m=(float(x + jitter[0]), float(y + jitter[1]), float(max(z + jitter[2], 0.5))),
            yaw_deg=float(yaw + jitter[3]), pitch_deg=float(pitch + jitter[4]), roll_deg=0.0, ego=ego,
        ))
    return tuple(cams)


def lamp_waveform(lamp: str, mains_hz: float = 50.0, lamp_depth: float | None = None, led_hz: float = 400.0,
                  led_duty: float = 0.5, led_phase: float = 0.0) -> Waveform:
    """The light of a lamp of type ``lamp`` (see ``LAMP_TYPES``): on the mains or, for 'led', PWM-dimmed."""
    if lamp == "led":
        return Waveform.pwm(led_hz, led_duty, led_phase, 1.0 if lamp_depth is None else lamp_depth)
    if lamp not in LAMPS:
        raise ConfigError(f"lamp {lamp!r} is not one of {list(LAMP_TYPES)}")
    return Waveform.mains(lamp, mains_hz, lamp_depth)


def street_lights(time_of_day: str, lighting: Lighting, *, lamps: str = "auto", lamp: str = "sodium",
                  mains_hz: float = 50.0, lamp_depth: float | None = None, led_hz: float = 400.0,
                  led_duty: float = 0.5, led_phase: float = 0.0) -> tuple[Lighting, tuple[ModulatedLight, ...]]:
    """The street's steady lighting and its modulated lights: street lamps and PWM LED signs.

    ``lamps`` 'auto' turns them on at dusk and night, 'on' always, 'off' never. The lamps light every surface
    (ambient) and the ground from above in their colour; the signs take over the lit windows' and shop
    fronts' glow (so the time-averaged frame keeps the time of day's look).
    """
    if lamps not in ("auto", "on", "off"):
        raise ConfigError(f"lamps {lamps!r} is not one of auto, on, off")
    on = lamps == "on" or (lamps == "auto" and time_of_day in LAMP_TIMES)
    if not on:
        return lighting, ()
    wave = lamp_waveform(lamp, mains_hz, lamp_depth, led_hz, led_duty, led_phase)
    rgb = _LAMP_RGB[lamp]
    out = [ModulatedLight("street lamps", wave, tuple(_LAMP_AMBIENT * c for c in rgb),
                          tuple(_LAMP_OVERHEAD * c for c in rgb))]
    if lighting.window_glow > 0:
        out.append(ModulatedLight("signs", Waveform.pwm(led_hz, led_duty, led_phase), glow=lighting.window_glow))
        lighting = replace(lighting, window_glow=0.0)
    return lighting, tuple(out)


CONTACT_SHADOW = 0.55
"""How much of the ground's light a walker's contact shadow takes at its centre (it falls to none at its rim)."""


def make_street_scene(
    seed: int = 0,
    *,
    time_of_day: str = "noon",
    speed: str | float = "normal",
    n_pedestrians: int = 20,
    n_cameras: int = 5,
    width: int = 1920,
    height: int = 1080,
    focal_mm: float = STUDY_FOCAL_MM,
    sensor_width_mm: float = STUDY_SENSOR_WIDTH_MM,
    ego: EgoMotion | None = None,
    props: bool = False,
    shadows: bool = True,
    **lamp_options: Any,
) -> Scene:
    """A seeded city street with a crowd walking on the sidewalks and crossing lanes, and several cameras.

    Walkers' base speeds are drawn up to 2 m/s and scaled by ``speed`` ('normal' 1x, 'fast' 10x).
    ``props`` adds parked cars, trees, lamp poles, signs, benches and bins (``rollcam.sim.streetprops``, from
    their own generator: the rest of the scene is the same either way). ``shadows`` (on by default) darkens the
    ground under each walker's feet (``CONTACT_SHADOW`` at the centre: the sky and sun the body hides from the
    ground there) and, in daylight, along its sun shadow (``rollcam.sim.render.tables``).
    ``lamp_options`` are ``street_lights``' (street lamps and LED signs, on at dusk and night by default).
    """
    if time_of_day not in TIMES_OF_DAY:
        raise ConfigError(f"time_of_day {time_of_day!r} is not one of {list(TIMES_OF_DAY)}")
    if n_pedestrians < 0 or n_cameras < 1:
        raise ConfigError(f"need n_pedestrians >= 0 and n_cameras >= 1, got {n_pedestrians!r}, {n_cameras!r}")
    mult = parse_speed(speed)
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"seed must be an integer >= 0, got {seed!r}")
    rng = np.random.default_rng(seed)
    road_half = float(rng.uniform(3.2, 5.5))
    sidewalk = float(rng.uniform(3.0, 5.0))
    length = 240.0
    street = Street(road_half, sidewalk, length, (), texture_seed=int(rng.integers(1 << 30)),
                    crosswalk_y_m=float(rng.uniform(-8, 18)))
    buildings = _facades(np.random.default_rng([seed, FACADE_STREAM]), _buildings(rng, length))
    street = Street(road_half, sidewalk, length, buildings, texture_seed=street.texture_seed,
                    crosswalk_y_m=street.crosswalk_y_m,
                    asphalt_color=tuple(float(v) for v in rng.uniform(0.07, 0.14) * np.array([1, 1, 1.08])),
                    sidewalk_color=tuple(float(v) for v in rng.uniform(0.3, 0.45) * np.array([1.0, 0.96, 0.9])))
    walk_lo = road_half + street.curb_width_m + 0.4
    walk_hi = street.facade_x_m - 0.5
    peds = []
    for i in range(n_pedestrians):
        side = -1.0 if rng.random() < 0.5 else 1.0
        lane_x = side * float(rng.uniform(walk_lo, walk_hi))
        if rng.random() < 0.15:
            lane_x = float(rng.uniform(-road_half + 0.5, road_half - 0.5))  # walking in the road
        base_speed = float(rng.uniform(0.8, 2.0))
        peds.append(make_pedestrian(rng, i + 1, lane_x, float(rng.uniform(-6, 6)), float(rng.uniform(14, 32)),
                                    base_speed * mult))
    peds = _crowd_behaviour(np.random.default_rng([seed, CROWD_STREAM]), peds, walk_lo, walk_hi)
    peds = _outfits(np.random.default_rng([seed, OUTFIT_STREAM]), peds)
    cams = _street_cameras(rng, street, n_cameras, width, height, focal_mm, sensor_width_mm,
                           ego if ego is not None else EgoMotion())
    lighting, lights = street_lights(time_of_day, TIMES_OF_DAY[time_of_day], **lamp_options)
    clutter = street_props(int(seed), street, peds, cams) if props else ()
    return Scene("street", seed, lighting, cams, street=street, pedestrians=tuple(peds), lights=lights,
                 props=clutter, contact_shadow=CONTACT_SHADOW if shadows else 0.0)


def make_chart_scene(seed: int = 0, *, vx_px_s: float = 2000.0, pitch_px: float = 64.0, bar_width_px: float = 24.0,
                     width: int = 1920, height: int = 1080, focal_mm: float = STUDY_FOCAL_MM,
                     sensor_width_mm: float = STUDY_SENSOR_WIDTH_MM) -> Scene:
    """Moving-target chart: dark vertical bars sliding at ``vx_px_s`` px/s across a light board.

    On a rolling-shutter sensor each bar edge shears by ``vx * line_time`` px per row, the classic way to
    measure a sensor's line time from its images.
    """
    for name, v in (("vx", vx_px_s), ("pitch", pitch_px), ("bar_width", bar_width_px)):
        if not math.isfinite(v):
            raise ConfigError(f"chart {name} must be finite, got {v!r}")
    if pitch_px <= 0 or not 0 < bar_width_px < pitch_px:
        raise ConfigError(f"chart needs 0 < bar_width < pitch, got bar_width={bar_width_px!r}, pitch={pitch_px!r}")
    n = int(math.ceil((width + 2 * pitch_px) / pitch_px)) + 1
    bars = tuple(ChartBar(i + 1, (i - 1) * pitch_px, bar_width_px) for i in range(n))
    cam = Camera("chart", width, height, focal_mm, sensor_width_mm, (0.0, 0.0, 1.0))
    return Scene("chart", seed, TIMES_OF_DAY["noon"], (cam,), chart=Chart(vx_px_s, pitch_px, bars))


def make_flat_scene(seed: int = 0, *, level: float = 0.5, width: int = 1920, height: int = 1080) -> Scene:
    """A uniform flat field of linear radiance ``level`` (for sensor characterisation)."""
    if not math.isfinite(level) or level < 0:
        raise ConfigError(f"flat level must be a finite number >= 0, got {level!r}")
    cam = Camera("flat", width, height, STUDY_FOCAL_MM, STUDY_SENSOR_WIDTH_MM, (0.0, 0.0, 1.0))
    return Scene("flat", seed, TIMES_OF_DAY["noon"], (cam,), flat_level=float(level))


def make_flicker_scene(seed: int = 0, *, lamp: str = "sodium", mains_hz: float = 50.0,
                       lamp_depth: float | None = None, led_hz: float = 400.0, led_duty: float = 0.5,
                       led_phase: float = 0.0, level: float = 0.5, width: int = 1920, height: int = 1080) -> Scene:
    """Flicker calibration: a flat wall lit by one modulated lamp only, of mean radiance ``level``.

    A rolling shutter shows the lamp's bands (period ``1 / (f * line_time)`` lines), a global shutter a frame
    that changes brightness from frame to frame; nothing else in view changes.
    """
    if not math.isfinite(level) or level < 0:
        raise ConfigError(f"flicker wall level must be a finite number >= 0, got {level!r}")
    wave = lamp_waveform(lamp, mains_hz, lamp_depth, led_hz, led_duty, led_phase)
    cam = Camera("flicker", width, height, STUDY_FOCAL_MM, STUDY_SENSOR_WIDTH_MM, (0.0, 0.0, 1.0))
    return Scene("flicker", seed, TIMES_OF_DAY["noon"], (cam,), flat_level=0.0,
                 lights=(ModulatedLight(lamp, wave, level=float(level)),))


def ego_preset(name: str) -> EgoMotion:
    """Named camera ego-motions: 'none', 'pan' (30 deg/s), 'walk' (handheld), 'vehicle' (10 m/s + vibration),
    'drone', and 'calib' (a camera-IMU calibration excitation: rotation only, sinusoidal about all three axes).

    'calib' is what a calibration engineer does by hand, waving the rig in front of a target: its angular
    velocity swings through zero (up to ~30 deg/s, ~12 rad/s^2), which makes the camera-IMU time offset
    observable (a constant pan shifts every image by the same amount whatever the offset), and it does not
    translate, so a pure-rotation model explains every feature track (``rollcam.host.correction.calibrate``).
    """
    presets = {
        "none": EgoMotion(),
        "pan": EgoMotion(pan_dps=30.0),
        "walk": EgoMotion(velocity_mps=(0.0, 1.4, 0.0), vibration_deg=0.4, vibration_m=0.01, vibration_hz=2.0),
        "vehicle": EgoMotion(velocity_mps=(0.0, 10.0, 0.0), pan_dps=2.0, vibration_deg=0.15, vibration_m=0.005,
                             vibration_hz=12.0),
        "drone": EgoMotion(pan_dps=20.0, tilt_dps=-5.0, roll_dps=10.0, velocity_mps=(2.0, 3.0, 0.0),
                           vibration_deg=0.3, vibration_m=0.002, vibration_hz=60.0),
        "calib": EgoMotion(vibration_deg=1.5, vibration_hz=3.0),
    }
    if name not in presets:
        raise ConfigError(f"ego-motion {name!r} is not one of {list(presets)}")
    return presets[name]


def make_scene(kind: str = "street", seed: int = 0, **options: Any) -> Scene:
    """Build a scene by kind ('street', 'chart', 'flat', 'flicker': the option table's ``SCENE_KINDS``) with that
    kind's keyword options."""
    makers = {"street": make_street_scene, "chart": make_chart_scene, "flat": make_flat_scene,
              "flicker": make_flicker_scene}
    if kind not in makers:
        raise ConfigError(f"scene {kind!r} is not one of {list(makers)}")
    try:
        return makers[kind](seed, **options)
    except TypeError as exc:
        raise ConfigError(f"bad option for scene {kind!r}: {exc}") from None
