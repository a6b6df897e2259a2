"""Row timing of real cameras: line times from a named hw_config, so RS-aware code works on hardware too.

A real camera reports a frame's timestamp and (sometimes) exposure but not when each row was read. Naming
the sensor (``?sensor=imx219``, or a scheme's known default such as the OAK's IMX378) gives each Frame the
line time of that sensor's readout at the delivered size (``resolve_settings``: the mode of that size, or
the readout rescaled to the delivered lines). Without a sensor a Frame says ``shutter='unknown'`` and
``line_time_ns=0``, so nothing mistakes an unknown camera for a global shutter.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError, SourceError
from rollcam.sim.frame import Frame
from rollcam.sim.hwconfig import load_sensor
from rollcam.sim.synthetic import resolve_settings
from rollcam.sim.timing import LineTiming, Readout, line_sample_times_ns

UNKNOWN_SHUTTER = "unknown"


@dataclass(frozen=True)
class RowTiming:
    """How a camera's rows are timed: sensor name (or None), shutter, readout and line timing."""

    sensor: str | None
    shutter: str
    readout: Readout
    timing: LineTiming | None

    @property
    def line_time_ns(self) -> int:
        """Nominal line time in ns; 0 for a global or unknown shutter."""
        return self.timing.line_time_ns if self.timing is not None and self.shutter == "rolling" else 0

    def row_times_ns(self, timestamp_ns: int, exposure_ns: int, n_lines: int) -> np.ndarray | None:
        """Sample time (mid-exposure) of each image line, or None when the timing is unknown."""
        if self.shutter == UNKNOWN_SHUTTER:
            return None
        t0 = int(timestamp_ns) + int(exposure_ns) // 2
        return line_sample_times_ns(t0, n_lines, self.timing if self.shutter == "rolling" else None, self.readout)

    def to_json(self) -> dict[str, Any]:
        """Plain data for ``info()``."""
        return {"sensor": self.sensor, "shutter": self.shutter, "readout": self.readout.value,
                "line_time_ns": self.line_time_ns}


UNKNOWN = RowTiming(None, UNKNOWN_SHUTTER, Readout.TOP_TO_BOTTOM, None)


def row_timing(sensor: str | None, width: int, height: int, uri: str) -> RowTiming:
    """The row timing of ``sensor`` delivering ``width`` x ``height`` frames; UNKNOWN when ``sensor`` is None."""
    if sensor is None:
        return UNKNOWN
    try:
        cfg = load_sensor(sensor)
        s = resolve_settings(cfg, size=(width, height))
    except ConfigError as exc:
        raise SourceError(f"source {uri!r}: option sensor={sensor!r} is invalid ({exc})") from None
    return RowTiming(cfg.name, s.shutter, s.readout, s.timing)


class FrameTimer:
    """Builds Frames of a real camera: keeps the row timing in step with the delivered size."""

    def __init__(self, sensor: str | None, uri: str) -> None:
        self.sensor, self.uri = sensor, uri
        self._size: tuple[int, int] | None = None
        self.timing = UNKNOWN
        if sensor is not None:  # check the name now, so a typo fails at open and not at the first frame
            row_timing(sensor, 640, 480, uri)

    def frame(self, data: np.ndarray, fmt: str, sequence: int, timestamp_ns: int, exposure_ns: int = 0,
              meta: dict[str, Any] | None = None) -> Frame:
        """A Frame of ``data`` with row times from the sensor's timing at this frame's size."""
        h, w = data.shape[:2]
        if self._size != (w, h):
            self._size = (w, h)
            self.timing = row_timing(self.sensor, w, h, self.uri)
        t = self.timing
        return Frame(data=data, format=fmt, sequence=int(sequence), timestamp_ns=int(timestamp_ns),
                     line_time_ns=t.line_time_ns, readout=t.readout, exposure_ns=int(exposure_ns), shutter=t.shutter,
                     row_times_ns=t.row_times_ns(timestamp_ns, exposure_ns, w if t.readout.by_column else h),
                     meta=dict(meta or {}))
