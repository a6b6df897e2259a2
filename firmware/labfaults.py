"""Lab faults that change what the camera makes, as a transport applies them to the frames it sends.

A camera HIL rig replaces frames on the link (grey and black test frames, a frozen image) and resets the
sensor's registers under a running stream; ``FrameFaults`` does both for one transport, decided by the device
frame number through the transport's ``FaultInjector`` (``rollcam.common.faults``), so every run with the same
plan hits the same frames. The frame-counter faults are the injector's ``sequence``; the sensor defects are
made by the sensor model itself (``rollcam.sim.defects``): ``FrameFaults`` programs the plan's into the camera's
spec (``CameraSpec.defects``) and counts the bursts the frames' truth reports; the AI Camera's faults
(``loaderfail``, ``fetimeout``, ``dnn_us``) go to the camera's in-sensor stage (``InSensorStage.set_faults``).

- ``grey``: the frame's image is mid-grey (half the format's full scale: BGR 128, raw samples at half their
  range), as a rig's "grey pattern" frame.
- ``black``: the image is black (BGR 0; raw samples at the sensor's black level).
- ``frozen``: the image is the previous frame's again (as this transport sent it); the stream's first frame
  has none to repeat and is never frozen.
- ``regreset``: before the frame is made public, the sensor's controls return to the defaults the transport
  noted when it opened the camera (``FirmwareCamera.reset_controls``; counted in the camera's
  ``stats.register_resets``, which the serial ``STATS?`` shows); the next frames are made with them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
from rollcam.common.faults import IMAGE_FAULTS, FaultInjector
from rollcam.sim.codecs import Levels, codec
from rollcam.sim.defects import SensorDefects
from rollcam.sim.frame import Frame

from .camera import FirmwareCamera


class FrameFaults:
    """One transport's image faults and register resets (see the module docstring)."""

    def __init__(self, injector: FaultInjector, camera: FirmwareCamera | None = None,
                 on_reset: Callable[[], None] | None = None) -> None:
        self.injector = injector
        plan = injector.plan
        # Only a firmware camera has a sensor (``rollcam view`` streams other sources through the same server).
        firmware = camera if isinstance(camera, FirmwareCamera) else None
        defects = SensorDefects.of(plan)
        if firmware is not None and defects is not None and firmware.spec.defects != defects:
            firmware.reprogram(dataclasses.replace(firmware.spec, defects=defects))
        if firmware is not None and plan.insensor_faults:  # the AI Camera's faults are its in-sensor stage's
            firmware.insensor.set_faults(plan)
        self.camera = firmware if plan.rate("regreset") else None
        self.defaults = self.camera.resettable_controls() if self.camera is not None else {}
        """The controls a register reset restores: the camera's when the transport opened it."""
        self.on_reset = on_reset
        """Called just before a register reset (the V4L2 driver notes the controls, to announce their change)."""
        self._previous: list[Frame] | None = None
        self.active = any(plan.rate(k) for k in (*IMAGE_FAULTS, "regreset", "burst"))

    def apply(self, frame: Frame, index: int) -> Frame:
        """``frame`` (device frame ``index``) as the plan leaves it: its image replaced, and the camera's registers
        reset after it when the plan says so. Without such faults the frame is returned untouched."""
        return self.apply_all([frame], index)[0]

    def apply_all(self, frames: list[Frame], index: int) -> list[Frame]:
        """``apply`` for the frames of one instant (a GS/RS pair), decided and counted once."""
        if not self.active:
            return frames
        inj = self.injector
        if frames[0].meta.get("defects", {}).get("burst"):  # the sensor model's burst, by the same draw
            inj.count("burst")
        if self.camera is not None and inj.hit("regreset", index):
            if self.on_reset is not None:
                self.on_reset()
            self.camera.reset_controls(self.defaults)
        previous = self._previous
        if previous is None or len(previous) != len(frames):
            previous = [None] * len(frames)
        kinds = IMAGE_FAULTS if previous[0] is not None else IMAGE_FAULTS[:2]
        kind = inj.first(kinds, index) if frames[0].data.size else None
        if kind is not None:
            frames = [faulted_image(f, kind, p) for f, p in zip(frames, previous, strict=True)]
        self._previous = frames
        return frames

def faulted_image(frame: Frame, kind: str, previous: Frame | None = None) -> Frame:
    """``frame`` with its image replaced as image fault ``kind`` (``IMAGE_FAULTS``) does, in the frame's own
    format, and its object truth with what the image shows; ``previous`` is the frame ``frozen`` repeats (same
    size and format, else the frame is kept)."""
    if kind == "frozen":
        if previous is None or previous.format != frame.format or previous.data.shape != frame.data.shape:
            return frame
        data, objects = previous.data, previous.objects
    else:
        data, objects = flat_image(frame, 0.5 if kind == "grey" else 0.0), None if frame.objects is None else ()
    # The truth follows the picture: a frozen image shows the previous frame's objects, a flat one none.
    return dataclasses.replace(frame, data=data, objects=objects, meta={**frame.meta, "image_fault": kind})


def flat_image(frame: Frame, level: float) -> np.ndarray:
    """Frame data of ``frame``'s size and format holding one level everywhere: ``level`` (0..1) of the way from
    black to full scale (raw samples from the sensor's black level, when the frame records it)."""
    c = codec(frame.format)
    w, h = frame.width, frame.height
    if c.raw:
        layout = c.layout
        assert layout is not None
        full = (1 << layout.bits) - 1
        levels = Levels.of_frame(frame)
        black = 0.0 if levels is None else levels.isp(layout).black_level_dn
        value = round(black + level * (full - black)) if level else round(black)
        return c.encode(np.full((h, w), value, np.uint16))
    return c.encode(np.full((h, w, 3), round(level * 255 + 0.01 if level else 0), np.uint8))

