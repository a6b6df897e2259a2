"""The in-sensor inference stage: the camera's network run on each frame the device makes, on the device clock.

``InSensorStage`` (one per ``FirmwareCamera``) sits after the sensor model: ``FirmwareCamera.make`` hands it each
frame with the ADC samples behind it, and it returns the frame carrying its in-sensor results
(``Frame.insensor``, ``rollcam.sim.insensor.InSensorResult``). The timing is a model of one accelerator that
runs one inference at a time, decided on the device clock alone (so the same stream gives the same results
however fast the host renders):

- frame ``n``'s input is complete at ``input_ns``: its last line's end of exposure (the sensor has the whole
  frame then); the inference takes ``latency = MACs / throughput`` (``InSensorConfig.accel``) and is done at
  ``done_ns = input_ns + latency``;
- a frame whose input is complete while the accelerator is still busy with an earlier frame is not inferred
  (skipped, as a sensor that is over budget drops it: counted in ``CameraStats.insensor_skipped``); with a
  latency of k frame periods, every (k+1)-th frame is inferred;
- a frame carries the results done since the previous frame's input was complete, up to its own
  (``(input_ns of n-1, input_ns of n]``), so with any latency > 0 a result rides on a later frame; its ``seq``
  says which frame it came from. A latency of 0 puts each result on its own frame. When frames were skipped
  (never made: a consumer too slow), "the previous frame" is the last one made, so no result is lost.

The network's input is the raw mosaic (``insensor_input=raw``: the ADC samples, whatever format the stream sends)
or the ISP's picture (``isp``), of the region ``insensor_roi`` (the whole frame by default), binned by the smallest
whole factor that fits ``insensor_size``; boxes come back in the frame's pixels. Frames are made ahead and made
again after a change (``emu.pump``), so the stage keeps the last ``KEEP`` frames' runs by sequence number, as
``firmware.imu.FrameImu`` does: a frame made again for the same start reuses its run, and one made from a new start
forgets the runs made ahead after it.
In metadata-only mode (``insensor_output=meta``) the frame's image is dropped here: ``data`` is empty and
``meta['image']`` is False; size, timing and results remain.
"""

from __future__ import annotations

import dataclasses
import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from rollcam.sim import formats as sf
from rollcam.sim.codecs import codec, preview_frame
from rollcam.sim.frame import Frame
from rollcam.sim.insensor import InSensorResult

from .imu import frame_end_ns
from .insensor import InSensorConfig, Network, load_network, roi_in
from .spec import CameraSpec

NO_IMAGE = np.zeros((0,), np.uint8)
"""A metadata-only frame's data."""


def bin_factor(size: tuple[int, int], max_size: tuple[int, int]) -> int:
    """The smallest whole factor that brings ``size`` (W, H) within ``max_size``."""
    w, h = size
    mw, mh = max_size
    return max(1, -(-w // mw), -(-h // mh))


def bin_mosaic(samples: np.ndarray, k: int, cfa: str) -> np.ndarray:
    """A mosaic binned by ``k``: each output site the mean of the k x k input sites of its own colour (a Bayer
    tile of 2k x 2k becomes one 2 x 2 tile), rounded; lines and columns beyond a whole tile are cut."""
    if k == 1:
        return samples
    h, w = samples.shape
    if cfa == "mono":
        a = samples[: h - h % k, : w - w % k].reshape(h // k, k, w // k, k)
        return np.rint(a.mean(axis=(1, 3))).astype(samples.dtype)
    t = 2 * k
    a = samples[: h - h % t, : w - w % t].reshape(h // t, k, 2, w // t, k, 2)
    binned = np.rint(a.mean(axis=(1, 4))).astype(samples.dtype)  # (H/2k, 2, W/2k, 2)
    return binned.reshape(2 * (h // t), 2 * (w // t))


def network_input(cfg: InSensorConfig, spec: CameraSpec, frame: Frame, samples: np.ndarray | None
                  ) -> tuple[np.ndarray, int, int]:
    """The network's input image, its sample bits (8 for a picture) and the bin factor (boxes times it are
    frame pixels)."""
    x, y, w, h = roi_in(cfg.roi, (frame.width, frame.height), even=cfg.input == "raw")
    k = bin_factor((w, h), cfg.max_size)
    if cfg.input == "raw":
        if spec.raw:
            bits = sf.pixel_format(frame.format).bits
            mosaic = codec(frame.format).decode(frame.data, frame.width, frame.height)
        else:
            if samples is None:
                raise ValueError("insensor_input=raw on a frame made without the sensor model")
            bits, mosaic = spec.sensor.bit_depth, samples
        return bin_mosaic(mosaic[y:y + h, x:x + w], k, spec.bayer_order), bits, k
    image = preview_frame(frame) if spec.raw else frame.data
    image = image[y:y + h, x:x + w]
    if k > 1:
        import cv2

        image = cv2.resize(image, (w // k, h // k), interpolation=cv2.INTER_AREA)
    return image, 8, k


@dataclass
class _Run:
    """Frame ``seq``'s place on the accelerator: its start, input and done times (done None: skipped), the
    start of the window of results it carries, and its results by shutter (a GS/RS pair has two)."""

    start_ns: int
    input_ns: int
    done_ns: int | None
    window_from_ns: int
    results: dict[str, InSensorResult] = field(default_factory=dict)


class InSensorStage:
    """Runs a camera's in-sensor network frame by frame (see the module docstring); thread-safe."""

    KEEP = 32
    """Frames' runs remembered: more than the pump makes ahead, and the longest latency tracked, in frames."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._runs: dict[int, _Run] = {}

    def _place(self, spec: CameraSpec, frame: Frame, latency_ns: int, stats: Any) -> _Run:
        seq, start = frame.sequence, int(frame.timestamp_ns)
        run = self._runs.get(seq)
        if run is not None and run.start_ns == start:
            return run
        # A frame (re)made at seq invalidates the runs made ahead after it.
        self._runs = {k: v for k, v in self._runs.items() if seq - self.KEEP < k < seq}
        input_ns = frame_end_ns(spec, start)
        busy = max((r.done_ns for r in self._runs.values() if r.done_ns is not None), default=None)
        # The window starts at the input of the frame made before this one: a frame the device skipped was
        # never delivered, so the results due on it ride on the next frame made instead of being lost.
        before = self._runs[max(self._runs)] if self._runs else None
        window = before.input_ns if before is not None else input_ns - spec.settings.timing.frame_period_ns
        accepted = busy is None or busy <= input_ns
        run = _Run(start, input_ns, input_ns + latency_ns if accepted else None, window)
        self._runs[seq] = run
        if stats is not None:
            if accepted:
                stats.insensor_runs += 1
            else:
                stats.insensor_skipped += 1
        return run

    def make(self, spec: CameraSpec, imager: Any, seq: int, start_ns: int, shutter: str | None = None,
             stats: Any = None) -> Frame:
        """Frame ``seq`` from ``imager`` (``firmware.imaging.Imager``), through the network when ``spec`` has one."""
        if spec.insensor is None:
            return imager.render(spec, seq, start_ns, shutter)
        frame, samples = imager.render_samples(spec, seq, start_ns, shutter)
        return self.process(spec, frame, samples, stats)

    def ledger(self, spec: CameraSpec) -> Any:
        """``stream_ledger`` of ``spec`` with this stage's latest result."""
        return stream_ledger(spec, self)

    def process(self, spec: CameraSpec, frame: Frame, samples: np.ndarray | None, stats: Any = None) -> Frame:
        """``frame`` with the results done in its window; its image dropped in metadata-only mode."""
        cfg = spec.insensor
        assert cfg is not None
        net = load_network(cfg.network)
        image, bits, k = network_input(cfg, spec, frame, samples)
        macs = int(net.macs(image.shape[1], image.shape[0]))
        with self._lock:
            run = self._place(spec, frame, cfg.accel.latency_ns(macs), stats)
            todo = run.done_ns is not None and frame.shutter not in run.results
        if todo:  # the network runs off the lock: other transports' frames are not held up by it
            result = self._infer(net, cfg, frame, run, image, bits, k, macs)
            with self._lock:
                run.results.setdefault(frame.shutter, result)
        with self._lock:
            carried = tuple(r.results.get(frame.shutter) or next(iter(r.results.values()))
                            for _, r in sorted(self._runs.items())
                            if r.done_ns is not None and r.results
                            and run.window_from_ns < r.done_ns <= run.input_ns)
        meta = frame.meta
        data = frame.data
        if not cfg.image_sent:
            data, meta = NO_IMAGE, {**meta, "image": False}
        return dataclasses.replace(frame, data=data, meta=meta, insensor=carried)

    @staticmethod
    def _infer(net: Network, cfg: InSensorConfig, frame: Frame, run: _Run, image: np.ndarray, bits: int, k: int,
               macs: int) -> InSensorResult:
        out = net.run(image, bits)
        x, y, _, _ = roi_in(cfg.roi, (frame.width, frame.height), even=cfg.input == "raw")
        boxes = np.asarray(out.boxes, np.float32).reshape(-1, 4) * np.float32(k) + np.float32([x, y, x, y])
        assert run.done_ns is not None
        return InSensorResult(seq=frame.sequence, boxes=boxes, scores=out.scores, classes=out.classes,
                              timestamp_ns=int(frame.timestamp_ns), line_time_ns=int(frame.line_time_ns),
                              readout=frame.readout.value, exposure_ns=int(frame.exposure_ns),
                              input_ns=run.input_ns, done_ns=run.done_ns, input=str(cfg.input),
                              input_size=(int(image.shape[1]), int(image.shape[0])), macs=macs, network=net.name,
                              tensors=tuple((n, np.asarray(t)) for n, t in out.tensors))

    def recent(self, now_ns: int, since_seq: int = 0) -> list[InSensorResult]:
        """Results done by device time ``now_ns`` of frames from ``since_seq`` on, oldest first (the last
        ``KEEP`` frames'; the serial ``INSENSOR?`` query and the HTTP ``/insensor.jsonl`` stream read these)."""
        with self._lock:
            runs = sorted(self._runs.items())
        return [next(iter(r.results.values())) for seq, r in runs
                if seq >= since_seq and r.done_ns is not None and r.done_ns <= now_ns and r.results]

    def latest(self) -> InSensorResult | None:
        """The result of the latest frame inferred (whether or not it is done yet), or None."""
        with self._lock:
            runs = sorted(self._runs.items())
        done = [r for _, r in runs if r.results]
        return next(iter(done[-1].results.values())) if done else None

    def reset(self) -> None:
        """Forget every run (a new stream starts afresh)."""
        with self._lock:
            self._runs = {}


def stream_ledger(spec: CameraSpec, stage: InSensorStage | None = None) -> Any:
    """``rollcam.firmware.ledger.ledger`` of ``spec``'s stream, with the in-sensor network's MACs at its binned
    input and the output of its latest result (from ``stage``; none yet: no detections or tensors counted)."""
    from .ledger import ledger

    cfg = spec.insensor
    if cfg is None:
        return ledger(spec)
    _, _, w, h = roi_in(cfg.roi, spec.size, even=cfg.input == "raw")
    k = bin_factor((w, h), cfg.max_size)
    macs = int(load_network(cfg.network).macs(w // k, h // k))
    latest = stage.latest() if stage is not None else None
    if latest is None:
        return ledger(spec, macs=macs)
    return ledger(spec, detections=len(latest), tensor_bytes=latest.tensor_bytes(), macs=macs)
