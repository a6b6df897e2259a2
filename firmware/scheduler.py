"""When each frame, row and row band of a stream is due, in device time (integer ns).

A ``FrameSchedule`` is one stretch of constant timing: frame ``seq`` starts exposing its first line at
``epoch_ns + frame_start(seq - first_seq)``. Line ``k`` in readout order starts exposing ``line_offset(k)``
later under a rolling shutter (all lines together under a global one) and is read out, so due, at
``start + exposure + line_offset(k + 1)``: both shutters read lines out one line time apart.
"""

from __future__ import annotations

from dataclasses import dataclass

from rollcam.sim.timing import NS_PER_S, LineTiming


@dataclass(frozen=True)
class FrameSchedule:
    """Device times of the frames of a stream segment with constant timing and exposure."""

    timing: LineTiming
    epoch_ns: int
    first_seq: int
    exposure_ns: int
    n_lines: int
    rolling: bool = True

    def start_ns(self, seq: int) -> int:
        """Start of exposure of frame ``seq``'s first line."""
        return self.timing.frame_start_ns(seq - self.first_seq, self.epoch_ns)

    def line_start_ns(self, seq: int, line: int) -> int:
        """Start of exposure of line ``line`` (readout order) of frame ``seq``."""
        return self.start_ns(seq) + (int(self.timing.line_offset_ns(line)) if self.rolling else 0)

    def line_due_ns(self, seq: int, line: int) -> int:
        """Time line ``line`` (readout order) of frame ``seq`` has been read out."""
        return self.start_ns(seq) + self.exposure_ns + int(self.timing.line_offset_ns(line + 1))

    def frame_due_ns(self, seq: int) -> int:
        """Time the last line of frame ``seq`` has been read out (the frame is complete)."""
        return self.line_due_ns(seq, self.n_lines - 1)

    def band_lines(self, band: int, n_bands: int) -> tuple[int, int]:
        """Readout-order lines ``[first, end)`` of band ``band`` of ``n_bands``."""
        return band * self.n_lines // n_bands, (band + 1) * self.n_lines // n_bands

    def band_due_ns(self, seq: int, band: int, n_bands: int) -> int:
        """Time the last line of band ``band`` of ``n_bands`` of frame ``seq`` has been read out."""
        return self.line_due_ns(seq, self.band_lines(band, n_bands)[1] - 1)

    def seq_started_by(self, t_ns: int) -> int:
        """The last frame whose exposure started at or before ``t_ns`` (``first_seq - 1`` if none)."""
        if t_ns < self.epoch_ns:
            return self.first_seq - 1
        # frame_start(n) = floor(n * F * 1e9 / P) <= dt  <=>  n <= floor((dt * P + P - 1) / (F * 1e9)) roughly;
        # step back when the floor of the inverse overshoots.
        dt, per = t_ns - self.epoch_ns, self.timing.frame_period_pck * NS_PER_S
        n = (dt * self.timing.pixel_rate_hz) // per
        while self.timing.frame_start_ns(n + 1) <= dt:
            n += 1
        while n > 0 and self.timing.frame_start_ns(n) > dt:
            n -= 1
        return self.first_seq + n

    def first_due_from(self, seq: int, t_ns: int) -> int:
        """The first frame at or after ``seq`` that is not yet read out at ``t_ns`` (due at or after it).

        Closed form: a frame's due time is its start plus a constant (exposure and readout), so this is one
        ``seq_started_by`` away, whatever the length of a stall.
        """
        due_after_start = self.frame_due_ns(self.first_seq) - self.start_ns(self.first_seq)
        return max(seq, self.seq_started_by(t_ns - due_after_start - 1) + 1)
