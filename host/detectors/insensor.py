"""``insensor``: the detections the emulated camera's in-sensor network made, read off the frames as they arrive.

Not a detector that runs here: the camera (``emu:...&insensor=SPEC``, ``rollcam.firmware.insensor_stage``) ran
its network on the chip and each frame carries the results done since the previous one, each naming the frame
it came from. ``InSensorReader.pair(frame)`` keeps the last ``keep`` frames by sequence number and returns each
carried result with its own source frame (and so that frame's ground truth), so ``rollcam detect`` scores
in-sensor detections against the frame they were made on, exactly as it scores a host detector. Frames the
accelerator skipped (over budget) never get a result; results whose frame is no longer kept are dropped and
counted (``lost``). Option ``keep`` (frames remembered, default 64).
"""

from __future__ import annotations

import collections
from typing import ClassVar

import numpy as np
from rollcam.common.errors import SourceError
from rollcam.common.values import positive_int
from rollcam.sim.frame import Frame

from .base import PERSON, Detections, DetectorSpec


class InSensorReader:
    """Pairs the in-sensor results frames carry with the frames they came from (see the module docstring)."""

    name = "insensor"
    input = "device"
    class_names: ClassVar[dict[int, str]] = {PERSON: "person"}

    def __init__(self, keep: int = 64) -> None:
        self.keep = keep
        self._frames: collections.OrderedDict[int, Frame] = collections.OrderedDict()
        self.results = 0
        self.lost = 0

    def pair(self, frame: Frame) -> list[tuple[Frame, Detections]]:
        """The results ``frame`` carries, each with its source frame (``frame`` itself or an earlier one)."""
        if frame.insensor is None:
            raise SourceError(f"frame {frame.sequence} carries no in-sensor results: open the source with an "
                              "in-sensor network (e.g. emu:letsroll?size=320x180&insensor=personnet-raw)")
        self._frames[frame.sequence] = frame
        while len(self._frames) > self.keep:
            self._frames.popitem(last=False)
        out = []
        for r in frame.insensor:
            src = self._frames.get(r.seq)
            if src is None:
                self.lost += 1
                continue
            self.results += 1
            out.append((src, Detections(r.boxes, r.scores, r.classes)))
        return out

    def detect(self, image: np.ndarray) -> Detections:
        """Refused: in-sensor detections come with frames (``pair``), not from an image."""
        raise SourceError("the insensor detector reads results off the camera's frames; it does not run on images")

    def close(self) -> None:
        """Forget the frames kept."""
        self._frames.clear()

    def __repr__(self) -> str:
        return f"InSensorReader(keep={self.keep}, results={self.results}, lost={self.lost})"


def open_detector(spec: DetectorSpec) -> InSensorReader:
    """``insensor?keep=N``."""
    spec.check({"keep"})
    if spec.target:
        from rollcam.common.errors import ConfigError

        raise ConfigError(f"detector {spec.spec!r}: insensor takes no target; the network is the camera's "
                          "(insensor=SPEC on the source)")
    return InSensorReader(spec.get("keep", positive_int, 64))
