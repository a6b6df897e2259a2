"""The cameras the benchmarks time: built as ``emu:`` builds them, from a ``CameraSpec``.

A benchmark that timed a ``SyntheticCamera`` built by hand could time another camera than the one users stream
(another sensor serial, so other fixed-pattern noise; another scene default). ``camera`` takes the options
``emu:`` takes and returns the ``SyntheticCamera`` the emulator itself would render with, so its renderer,
exposure integration and sensor model can be timed directly.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rollcam.firmware.imaging import synthetic_camera
from rollcam.firmware.spec import CameraSpec
from rollcam.sim.hwconfig import SensorConfig
from rollcam.sim.synthetic import SyntheticCamera


def camera(sensor: SensorConfig | str, scene: Mapping[str, Any], **fields: Any) -> SyntheticCamera:
    """The ``SyntheticCamera`` of ``CameraSpec.create(sensor, scene=scene, **fields)``: ``scene`` is
    ``{'scene': kind, 'seed': n, <the kind's options>}`` as in an ``emu:`` URI, ``fields`` the spec's fields
    (``size``, ``pixel_format``, ``exposure_ns``, ``blur_px``, ``lens``, ``line_length_pck``...)."""
    return synthetic_camera(CameraSpec.create(sensor, scene=scene, **fields))
