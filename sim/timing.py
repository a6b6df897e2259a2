"""Integer-nanosecond sensor timing: line times from the pixel clock, per-row sample times, frame starts.

Every device time is an integer number of nanoseconds. A line lasts ``line_length_pck / pixel_rate_hz``
seconds, which is rarely a whole number of nanoseconds (imx219: 18,903.5 ns), so times are computed in
closed form from integers (``floor(n * line_length * 1e9 / pixel_rate)``), never by repeated addition:
frame 77 million of a 30-day stream has exactly the row times the closed form gives.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np

NS_PER_S = 1_000_000_000


class Readout(str, Enum):
    """Order in which a rolling-shutter sensor reads its lines (rows, or columns for column readout)."""

    TOP_TO_BOTTOM = "top_to_bottom"
    BOTTOM_TO_TOP = "bottom_to_top"
    LEFT_TO_RIGHT = "left_to_right"
    RIGHT_TO_LEFT = "right_to_left"

    @property
    def by_column(self) -> bool:
        """True when lines are image columns rather than rows."""
        return self in (Readout.LEFT_TO_RIGHT, Readout.RIGHT_TO_LEFT)

    @property
    def reversed(self) -> bool:
        """True when the last image line is read first."""
        return self in (Readout.BOTTOM_TO_TOP, Readout.RIGHT_TO_LEFT)

    @classmethod
    def parse(cls, value: str | Readout) -> Readout:
        """Accept the enum, its value, or the short forms ``tb``, ``bt``, ``lr``, ``rl``."""
        if isinstance(value, Readout):
            return value
        short = {"tb": "top_to_bottom", "bt": "bottom_to_top", "lr": "left_to_right", "rl": "right_to_left"}
        key = short.get(str(value).lower(), str(value).lower())
        try:
            return cls(key)
        except ValueError:
            from rollcam.common.errors import ConfigError

            raise ConfigError(
                f"readout {value!r} is not one of {[r.value for r in cls]} (or tb, bt, lr, rl)"
            ) from None


@dataclass(frozen=True)
class LineTiming:
    """Line timing of a sensor mode from its pixel clock: exact integer-ns offsets of any line or frame.

    ``frame_pck`` is the frame period in pixel clocks when it is not a whole number of lines (a rescaled
    readout keeps the sensor's frame period while spreading its lines); by default
    ``frame_length_lines * line_length_pck``.
    """

    pixel_rate_hz: int
    line_length_pck: int
    frame_length_lines: int
    frame_pck: int | None = None

    def __post_init__(self) -> None:
        for name in ("pixel_rate_hz", "line_length_pck", "frame_length_lines", "frame_pck"):
            value = getattr(self, name)
            if name == "frame_pck" and value is None:
                continue
            if not isinstance(value, (int, np.integer)) or value <= 0:
                from rollcam.common.errors import ConfigError

                raise ConfigError(f"LineTiming.{name} must be a positive integer, got {value!r}")

    @property
    def frame_period_pck(self) -> int:
        """Frame period in pixel clocks."""
        return self.frame_pck or self.frame_length_lines * self.line_length_pck

    @property
    def line_time_ns(self) -> int:
        """Nominal line time rounded to the nearest ns (the exact offsets come from ``line_offset_ns``)."""
        return (self.line_length_pck * NS_PER_S + self.pixel_rate_hz // 2) // self.pixel_rate_hz

    @property
    def frame_period_ns(self) -> int:
        """Frame period rounded down to whole ns (frame starts come from ``frame_start_ns``)."""
        return self.frame_start_ns(1)

    @property
    def fps(self) -> float:
        """Frame rate in frames per second."""
        return self.pixel_rate_hz / self.frame_period_pck

    def line_offset_ns(self, lines: np.ndarray | int) -> np.ndarray | int:
        """Offset from a frame's first line to line ``lines`` (scalar or array), floored to ns."""
        if isinstance(lines, (int, np.integer)):
            return int(lines) * self.line_length_pck * NS_PER_S // self.pixel_rate_hz
        arr = np.asarray(lines, dtype=np.int64)
        # floor(r * L * 1e9 / P) = r * q + floor(r * rem / P) with q, rem = divmod(L * 1e9, P): no int64
        # overflow for any line count and clock (r * rem < r * P), unlike the direct product.
        q, rem = divmod(self.line_length_pck * NS_PER_S, self.pixel_rate_hz)
        return arr * q + (arr * rem) // self.pixel_rate_hz

    def frame_start_ns(self, frame_index: int, epoch_ns: int = 0) -> int:
        """Start of frame ``frame_index`` counted from ``epoch_ns``; exact for any index (Python ints)."""
        return int(epoch_ns) + int(frame_index) * self.frame_period_pck * NS_PER_S // self.pixel_rate_hz


def line_sample_times_ns(
    t_start_ns: int,
    n_lines: int,
    timing: LineTiming | None,
    readout: Readout | str = Readout.TOP_TO_BOTTOM,
) -> np.ndarray:
    """Sample time of each image line (index = image row, or column for column readout), int64 ns.

    ``timing=None`` means a global shutter: every line at ``t_start_ns``. Otherwise line ``k`` in readout
    order is sampled at ``t_start_ns + timing.line_offset_ns(k)``; reversed readouts map the first read line
    to the last image line.
    """
    readout = Readout.parse(readout)
    if n_lines <= 0:
        from rollcam.common.errors import ConfigError

        raise ConfigError(f"n_lines must be positive, got {n_lines!r}")
    if timing is None:
        return np.full(n_lines, int(t_start_ns), dtype=np.int64)
    order = np.arange(n_lines, dtype=np.int64)
    if readout.reversed:
        order = order[::-1]
    return np.int64(t_start_ns) + timing.line_offset_ns(order)
