"""The scene as plain, frozen data: street layout, lighting, modulated lights, pedestrians, props, charts, cameras.

Everything moves analytically in time, so any instant can be evaluated directly (no stepping). Renderers,
sensor models and ground truth read a Scene and never mutate it. World frame: X across the street (east),
Y along it (north), Z up, metres; camera frame: x right, y down, z forward.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from .flicker import Waveform

RGB = tuple[float, float, float]


@dataclass(frozen=True)
class Lighting:
    """Light of one time of day, in linear relative radiance (noon sun on white ~ 1.0)."""

    name: str
    sun_azimuth_deg: float  # compass direction towards the sun, 0 = +Y (north), 90 = +X (east)
    sun_elevation_deg: float
    sun_rgb: RGB
    ambient_rgb: RGB  # diffuse sky light reaching a surface that faces the open sky
    sky_horizon_rgb: RGB
    sky_zenith_rgb: RGB
    haze_rgb: RGB
    fog_distance_m: float = 300.0
    window_glow: float = 0.0  # lit-window emission (dusk, dawn)

    @property
    def sun_direction(self) -> tuple[float, float, float]:
        """Unit vector from the ground towards the sun, world frame."""
        az, el = math.radians(self.sun_azimuth_deg), math.radians(self.sun_elevation_deg)
        return (math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el))


FACADES = ("plaster", "brick", "stone", "glass")
"""What a facade is built of: rendered plaster, brick in running bond, ashlar stone blocks, or a glass curtain
wall (a grid of panes in mullions, mirroring the street and the sky). The first three have the windows and shop
fronts; a curtain wall is glass from the first floor up."""


@dataclass(frozen=True)
class Building:
    """One facade segment along a side of the street: its extent, colours, window grid and material."""

    side: int  # -1: west facade (x = -facade_x), +1: east facade
    y0_m: float
    y1_m: float
    height_m: float
    color: RGB
    window_color: RGB
    floor_height_m: float = 3.2
    window_width_m: float = 1.2
    window_spacing_m: float = 2.6
    lit_fraction: float = 0.3
    material: str = "plaster"  # one of FACADES; on glass, `color` is the mullions' and `window_color` the panes'

    def __post_init__(self) -> None:
        if self.material not in FACADES:
            from rollcam.common.errors import ConfigError

            raise ConfigError(f"building at y {self.y0_m:g} m: material {self.material!r} is not one of "
                              f"{list(FACADES)}")


@dataclass(frozen=True)
class Street:
    """A straight street along Y: road, curbs, sidewalks and two rows of facades."""

    road_half_width_m: float
    sidewalk_width_m: float
    length_m: float  # the street spans y in [-length/2, length/2]
    buildings: tuple[Building, ...]
    asphalt_color: RGB = (0.10, 0.10, 0.11)
    sidewalk_color: RGB = (0.38, 0.36, 0.34)
    curb_width_m: float = 0.25
    crosswalk_y_m: float = 12.0
    texture_seed: int = 0

    @property
    def facade_x_m(self) -> float:
        """Distance from the street axis to the facades."""
        return self.road_half_width_m + self.curb_width_m + self.sidewalk_width_m


BAGS = ("none", "backpack", "shoulder")
"""What a walker may carry: nothing, a backpack, or a bag on a shoulder strap at the right hip."""


@dataclass(frozen=True)
class Pedestrian:
    """A walker going back and forth along a lane parallel to the street (turning at the lane's ends).

    Gait phase follows distance walked, so stride frequency follows speed (``speed / stride_length``).
    """

    id: int
    lane_x_m: float
    lane_y_center_m: float
    lane_half_length_m: float
    start_offset_m: float  # distance already walked at t = 0
    speed_mps: float
    height_m: float
    build: float  # girth scale, ~0.85 (slim) .. 1.25 (heavy)
    skin: RGB
    hair: RGB
    shirt: RGB
    pants: RGB
    shoes: RGB
    long_hair: bool = False
    long_sleeves: bool = True
    gait_phase: float = 0.0
    direction: int = 1  # +1 starts walking towards +Y, -1 towards -Y
    cls: str = "person"
    bag: str = "none"  # one of BAGS: what the walker carries
    bag_rgb: RGB = (0.08, 0.08, 0.09)
    skirt: bool = False  # a skirt instead of trousers: bare legs below it

    def __post_init__(self) -> None:
        if self.bag not in BAGS:
            from rollcam.common.errors import ConfigError

            raise ConfigError(f"pedestrian {self.id}: bag {self.bag!r} is not one of {list(BAGS)}")

    @property
    def stride_length_m(self) -> float:
        """Length of one full gait cycle (two steps)."""
        return 0.82 * self.height_m


PROP_KINDS = ("car", "tree", "pole", "sign", "bench", "bin")
"""Kinds of street prop: parked car, tree, lamp pole, traffic sign, bench, litter bin."""


@dataclass(frozen=True)
class Prop:
    """Static street clutter: a parked car, a tree, a lamp pole, a sign, a bench or a bin, standing on the ground.

    Props hide what is behind them (the walkers' visibility counts them) but are scenery, not objects: frames
    carry no truth record of them. Sizes are of the footprint's box (``length_m`` along Y, ``width_m`` along X)
    and the height; ``color`` is the body, bark, pole or seat, ``color2`` the windows, crown, lamp head, sign
    plate or bench legs. ``facing`` is +1/-1: the way a car's front points along Y, a sign's plate faces along Y,
    a bench's seat and a lamp's arm point along X.
    """

    kind: str
    x_m: float
    y_m: float
    length_m: float
    width_m: float
    height_m: float
    color: RGB
    color2: RGB
    facing: int = 1


@dataclass(frozen=True)
class ChartBar:
    """A vertical bar of a moving calibration chart, defined in image coordinates (pixels)."""

    id: int
    x0_px: float  # left edge at t = 0
    width_px: float
    color: RGB = (0.02, 0.02, 0.02)


@dataclass(frozen=True)
class Chart:
    """Moving-target chart: bars sliding horizontally at ``vx_px_s`` over a light board.

    Bars wrap around a period of ``pitch_px * len(bars)`` outside the image, so the chart runs forever.
    """

    vx_px_s: float
    pitch_px: float
    bars: tuple[ChartBar, ...]
    board_rgb: RGB = (0.75, 0.75, 0.75)


@dataclass(frozen=True)
class EgoMotion:
    """Camera motion: constant rates and velocity plus a three-axis sinusoidal vibration."""

    pan_dps: float = 0.0
    tilt_dps: float = 0.0
    roll_dps: float = 0.0
    velocity_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    vibration_deg: float = 0.0
    vibration_m: float = 0.0
    vibration_hz: float = 0.0

    @property
    def moving(self) -> bool:
        """True when the camera pose changes with time."""
        return any(
            v != 0.0
            for v in (self.pan_dps, self.tilt_dps, self.roll_dps, *self.velocity_mps)
        ) or (self.vibration_hz > 0 and (self.vibration_deg > 0 or self.vibration_m > 0))


@dataclass(frozen=True)
class Camera:
    """A pinhole camera: intrinsics from focal length and sensor width, a pose, optional ego-motion."""

    name: str
    width: int
    height: int
    focal_mm: float
    sensor_width_mm: float
    position_m: tuple[float, float, float]
    yaw_deg: float = 0.0  # 0 looks along +Y, 90 along +X
    pitch_deg: float = 0.0  # positive looks up
    roll_deg: float = 0.0
    ego: EgoMotion = field(default_factory=EgoMotion)

    @property
    def fx_px(self) -> float:
        """Focal length in pixels (square pixels)."""
        return self.focal_mm / self.sensor_width_mm * self.width

    def with_resolution(
        self, width: int, height: int, focal_mm: float | None = None, sensor_width_mm: float | None = None
    ) -> Camera:
        """The same pose at another resolution (and optionally other optics)."""
        return replace(
            self,
            width=int(width),
            height=int(height),
            focal_mm=self.focal_mm if focal_mm is None else float(focal_mm),
            sensor_width_mm=self.sensor_width_mm if sensor_width_mm is None else float(sensor_width_mm),
        )

    def mounted(self, offset_m: tuple[float, float, float], yaw_deg: float = 0.0) -> Camera:
        """This camera moved as one camera of a rig whose reference camera it is: ``offset_m`` is (right,
        forward, up) in its own level frame (a stereo baseline is ``(b, 0, 0)``), ``yaw_deg`` turns it to the
        right about the vertical. Pitch and roll are the reference camera's."""
        dx, dy, dz = (float(v) for v in offset_m)
        if (dx, dy, dz, float(yaw_deg)) == (0.0, 0.0, 0.0, 0.0):
            return self
        yaw = math.radians(self.yaw_deg)
        right, forward = (math.cos(yaw), -math.sin(yaw)), (math.sin(yaw), math.cos(yaw))
        x, y, z = self.position_m
        return replace(self, position_m=(x + dx * right[0] + dy * forward[0], y + dx * right[1] + dy * forward[1],
                                         z + dz), yaw_deg=self.yaw_deg + float(yaw_deg))


@dataclass(frozen=True)
class ModulatedLight:
    """A light whose output follows a periodic waveform (a mains lamp, a PWM LED), and what it lights.

    What it adds at the waveform's mean: ``ambient_rgb`` on every surface and walker, ``overhead_rgb`` as a
    light from straight above (lamp heads over the street), ``glow`` on lit windows and shop fronts, and
    ``level`` to a flat wall. The renderer scales that contribution, line by line, by the waveform's mean over
    the line's exposure window (``rollcam.sim.flicker``); the scene's ``lighting`` is the steady rest.
    """

    name: str
    waveform: Waveform
    ambient_rgb: RGB = (0.0, 0.0, 0.0)
    overhead_rgb: RGB = (0.0, 0.0, 0.0)
    glow: float = 0.0
    level: float = 0.0


@dataclass(frozen=True)
class Scene:
    """A complete scene: what is there (street or chart or flat field), its light, its actors, its cameras."""

    kind: str  # "street", "chart", "flat" or "flicker" (a flat wall under modulated light)
    seed: int
    lighting: Lighting
    cameras: tuple[Camera, ...]
    street: Street | None = None
    pedestrians: tuple[Pedestrian, ...] = ()
    chart: Chart | None = None
    flat_level: float = 0.5
    lights: tuple[ModulatedLight, ...] = ()  # time-modulated lights, on top of the steady ``lighting``
    props: tuple[Prop, ...] = ()  # street clutter (static actors without truth records)
    contact_shadow: float = 0.0  # ground darkening under each walker at its centre; > 0 also casts sun shadows

    @property
    def time_of_day(self) -> str:
        """Name of the lighting preset."""
        return self.lighting.name

    def camera(self, index_or_name: int | str = 0) -> Camera:
        """A camera by index or name."""
        from rollcam.common.errors import ConfigError

        if isinstance(index_or_name, str) and not index_or_name.isdigit():
            for cam in self.cameras:
                if cam.name == index_or_name:
                    return cam
            raise ConfigError(f"camera {index_or_name!r} not in scene: {[c.name for c in self.cameras]}")
        idx = int(index_or_name)
        if not 0 <= idx < len(self.cameras):
            raise ConfigError(f"camera index {idx!r} out of range 0..{len(self.cameras) - 1}")
        return self.cameras[idx]
