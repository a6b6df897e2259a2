"""Host-side rolling-shutter correction: the study's baseline pipeline, on the host instead of in the ISP.

``GyroCorrector`` keeps the IMU samples each frame delivers (``Frame.imu``) and unwarps every rolling-shutter
frame to the orientation of its first line (``rollcam.sim.rscorrect``: per-line rotation from the gyro,
rotation only, no parallax or object motion), using the calibration the frames carry (``Frame.imu.params``:
``T_cam_imu``, time offset) and the pinhole ``Frame.meta["intrinsics"]``. Lines whose instants the samples
received so far do not reach (a positive camera-IMU offset puts a frame's last lines' samples in the next
frame's block) are corrected with the edge sample's rate held, as a live stabiliser does. A global-shutter
frame passes unchanged. ``rollcam detect --correct gyro`` runs it before the detector.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np
from rollcam.common.errors import SourceError
from rollcam.sim.frame import Frame
from rollcam.sim.imu import ImuSamples
from rollcam.sim.rscorrect import correct_image

CORRECTIONS = ("gyro", "flow")
HISTORY_NS = 1_000_000_000


class GyroCorrector:
    """Corrects frames of one stream in order (see the module docstring)."""

    def __init__(self) -> None:
        self._samples: ImuSamples | None = None
        self.frames = 0

    def _add(self, samples: ImuSamples) -> ImuSamples:
        got = samples if self._samples is None else ImuSamples.concat([self._samples, samples])
        keep = got.t_ns >= got.t_ns[-1] - HISTORY_NS if len(got) else slice(None)
        self._samples = ImuSamples(got.index[keep], got.t_ns[keep], got.gyro[keep], got.accel[keep], got.params)
        return self._samples

    def correct(self, frame: Frame) -> Frame:
        """``frame`` unwarped to its first line's orientation (BGR), or unchanged for a global shutter."""
        from ..preview import frame_bgr

        if frame.imu is None or "intrinsics" not in frame.meta or frame.row_times_ns is None:
            raise SourceError(f"gyro correction needs frames with IMU samples and intrinsics (emu:...&imu=on); "
                              f"frame {frame.sequence} has none")
        samples = self._add(frame.imu)
        if frame.shutter != "rolling" or frame.line_time_ns == 0 or frame.meta.get("rs_correct"):
            return frame
        image, _ = gyro_correct(frame_bgr(frame), samples, frame.row_times_ns, tuple(frame.meta["intrinsics"]),
                                by_column=frame.readout.by_column)
        self.frames += 1
        return dataclasses.replace(frame, data=image, format="BGR3", meta={**frame.meta, "rs_correct": "gyro-host"})


def gyro_correct(image: np.ndarray, samples: ImuSamples, line_times_ns: np.ndarray,
                 intrinsics: tuple[float, float, float, float], *, by_column: bool = False
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``image`` unwarped to its first line's orientation from ``samples`` (edge rates held where they stop
    short of the lines); returns the image and the mask of pixels with a source."""
    times = np.asarray(line_times_ns, np.int64)
    held = _held(samples, int(times.min()), int(times.max()))
    return correct_image(image, held, times, int(times.min()), intrinsics, by_column=by_column)


def _held(s: ImuSamples, first_ns: int, last_ns: int) -> ImuSamples:
    """``s`` extended, by holding its edge samples, to measure camera times ``first_ns .. last_ns``."""
    off = s.params.time_offset_ns
    t, g, a, k = s.t_ns, s.gyro, s.accel, s.index
    if t[0] - off > first_ns:
        t, g, a, k = np.r_[first_ns + off, t], np.r_[g[:1], g], np.r_[a[:1], a], np.r_[k[:1] - 1, k]
    if t[-1] - off < last_ns:
        t, g, a, k = np.r_[t, last_ns + off], np.r_[g, g[-1:]], np.r_[a, a[-1:]], np.r_[k, k[-1:] + 1]
    return ImuSamples(k, t.astype(np.int64), g, a, s.params)


def correcting_reader(read: Callable[[], Frame | None], method: str) -> Callable[[], Frame | None]:
    """``read`` behind the named correction (``CORRECTIONS``)."""
    if method not in CORRECTIONS:
        raise SourceError(f"correction {method!r} is not one of {list(CORRECTIONS)}")
    from .flow import FlowCorrector

    corrector = FlowCorrector() if method == "flow" else GyroCorrector()

    def corrected() -> Frame | None:
        frame = read()
        return None if frame is None else corrector.correct(frame)
    return corrected


def imu_record(frame: Frame, device: Any) -> dict[str, Any] | None:
    """What a dataset keeps of a frame to gyro-correct its stored image later (JSON): the IMU's calibration,
    the samples of ``device`` (the emulated camera that made it) over the frame's lines, two more each side,
    and the pinhole intrinsics; None for a frame without an IMU. Not the block the frame carried: a stream's
    first frame carries one frame period up to its end, which a long exposure's first lines precede."""
    from rollcam.firmware.imu import device_samples

    if frame.imu is None or "intrinsics" not in frame.meta or frame.row_times_ns is None:
        return None
    p = frame.imu.params
    margin = 2 * (10**9 // p.rate_hz)
    t0 = int(frame.row_times_ns.min()) + p.time_offset_ns - margin
    t1 = int(frame.row_times_ns.max()) + p.time_offset_ns + margin
    samples = device_samples(device, t0, 10**6, now_ns=t1)
    return {"params": dataclasses.asdict(p), "samples": samples.to_rows(),
            "intrinsics": [float(v) for v in frame.meta["intrinsics"]]}


def line_times(first_ns: int, last_ns: int, n_lines: int) -> np.ndarray:
    """Line times (image order) from the first and last image line's: line offsets are linear, to the ns."""
    return np.round(np.linspace(float(first_ns), float(last_ns), int(n_lines))).astype(np.int64)


def correct_stored(image: np.ndarray, imu: dict[str, Any], line_times_ns: np.ndarray, *, by_column: bool = False
                   ) -> np.ndarray:
    """A stored RS image (8-bit BGR) gyro-corrected from its ``imu_record``."""
    from rollcam.sim.imu import ImuParams

    if not imu["samples"]:
        raise SourceError("the stored IMU block holds no samples")
    params = ImuParams(**{k: tuple(v) if isinstance(v, list) else v for k, v in imu["params"].items()})
    rows = np.asarray(imu["samples"], np.float64).reshape(-1, 7)
    t_ns = np.asarray([int(r[0]) for r in imu["samples"]], np.int64)  # exact: not through float64
    samples = ImuSamples(np.arange(len(t_ns)), t_ns, rows[:, 1:4], rows[:, 4:7], params)
    out, _ = gyro_correct(image, samples, line_times_ns, tuple(imu["intrinsics"]), by_column=by_column)
    return out
