"""Scene controls of the firmware camera: which synthetic scene it looks at, as validated plain options."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rollcam.common.errors import ConfigError
from rollcam.sim.scene import Scene
from rollcam.sim.scenegen import ego_preset, make_scene


def _text(v: Any) -> str:
    return str(v)


SCENE_OPTIONS: dict[str, dict[str, tuple[str, Callable[[Any], Any]]]] = {
    "street": {"time": ("time_of_day", _text), "speed": ("speed", _text), "pedestrians": ("n_pedestrians", int),
               "ego": ("ego", ego_preset)},
    "chart": {"vx": ("vx_px_s", float)},
    "flat": {"level": ("level", float)},
}
"""scene kind -> option name -> (make_scene keyword, converter)."""


def build_scene(options: dict[str, Any], width: int, height: int) -> Scene:
    """A scene from options ``{'scene': kind, 'seed': n, <kind's options>}``; bad ones name the option."""
    kind = str(options.get("scene", "street"))
    if kind not in SCENE_OPTIONS:
        raise ConfigError(f"scene {kind!r} is not one of {list(SCENE_OPTIONS)}")
    allowed = SCENE_OPTIONS[kind]
    kwargs: dict[str, Any] = {"width": width, "height": height}
    for key, value in options.items():
        if key in ("scene", "seed"):
            continue
        if key not in allowed:
            raise ConfigError(f"scene option {key!r} does not apply to scene {kind!r}; options: "
                              f"{['scene', 'seed', *allowed]}")
        name, conv = allowed[key]
        try:
            kwargs[name] = conv(value)
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"scene option {key}={value!r} is invalid ({exc})") from None
    try:
        seed = int(options.get("seed", 0))
    except (TypeError, ValueError):
        raise ConfigError(f"scene option seed={options.get('seed')!r} is not an integer") from None
    if seed < 0:
        raise ConfigError(f"scene option seed={seed!r} must be >= 0")
    return make_scene(kind, seed, **kwargs)
