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
again after a change (``emu.pump``), so the stage keeps the runs of the last ``KEEP`` frames made, as
``firmware.imu.FrameImu`` does: a frame made again for the same start reuses its run, and one made from a new start
forgets the runs made ahead after it.
With an input tensor (``insensor_tensor``) the network's input is the IMX500's: the ISP's picture of the region,
cropped and scaled to the tensor and quantised (``rollcam.firmware.input_tensor``); the network runs on the picture
the tensor shows and the result carries the tensor (``InSensorResult.input_tensor``). ``inject`` puts a tensor in
the place of the next frame's, as Sony's data injection does on a real AI Camera: the frame it names (the
"comparison frame") runs the network on the injected tensor if the accelerator takes that frame; if it is busy
then, the injection is missed (counted) and the caller injects again. A second tensor while one waits is refused
(``InjectionBusy``, EREMOTEIO as the real sensor's driver answers).
The AI Camera's own failures are injected here (``set_faults``, from the ``faults=`` plan of the door that opened
the camera; ``rollcam.common.faults``): ``loaderfail=MS`` makes every frame from MS ms after the first one fail
with ``LoaderFailure`` ("failed to load loader firmware"), ``fetimeout`` fails the frames from the first hit on
with ``FrontendTimeout`` ("Camera frontend has timed out!"), each counted once in ``CameraStats``
(``loader_failures``, ``frontend_timeouts``; serial ``STATS?``) until the stage is reset; ``dnn_us=N`` makes
every inference take N us, so a network slower than the frame rate skips frames (``insensor_skipped``), and the
frames that carry no result are those a client sees without output tensors.
In metadata-only mode (``insensor_output=meta``) the frame's image is dropped here: ``data`` is empty and
``meta['image']`` is False; size, timing and results remain.
"""

from __future__ import annotations

import dataclasses
import errno
import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError, DeviceError
from rollcam.common.faults import FaultPlan
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


Place = tuple[float, float, float, float]
"""How the network's boxes become frame pixels: x and y scale, then x and y offset."""


class InjectionBusy(DeviceError):
    """A tensor was injected while the previous one still waits for its frame (``errno`` EREMOTEIO)."""

    errno = errno.EREMOTEIO


class LoaderFailure(DeviceError):
    """The IMX500's firmware loader failed (an injected ``loaderfail``): the camera makes no more frames."""


class FrontendTimeout(DeviceError):
    """The receiver's front end timed out (an injected ``fetimeout``): the camera makes no more frames."""


LOADER_FAILURE = "imx500: failed to load loader firmware"
FRONTEND_TIMEOUT = "Camera frontend has timed out!"


def tensor_input(cfg: InSensorConfig, spec: CameraSpec, frame: Frame) -> tuple[np.ndarray, np.ndarray, Place]:
    """The IMX500 input tensor of a frame (``cfg.tensor``): the tensor, the picture it shows (BGR, the tensor's
    size) and where its pixels lie in the frame's."""
    fmt = cfg.tensor
    assert fmt is not None
    x, y, w, h = roi_in(cfg.roi, (frame.width, frame.height), even=False)
    picture = preview_frame(frame) if spec.raw else frame.data
    tensor = fmt.prepare(np.ascontiguousarray(picture[y:y + h, x:x + w]))
    cx, cy, cw, ch = fmt.crop((w, h))
    return tensor, fmt.picture_bgr(tensor), (cw / fmt.width, ch / fmt.height, x + cx, y + cy)


@dataclass
class _Run:
    """Frame ``seq``'s place on the accelerator: its start, input and done times (done None: skipped), the
    start of the window of results it carries, and its results by shutter (a GS/RS pair has two)."""

    start_ns: int
    input_ns: int
    done_ns: int | None
    window_from_ns: int
    results: dict[str, InSensorResult] = field(default_factory=dict)
    injected: np.ndarray | None = None


class InSensorStage:
    """Runs a camera's in-sensor network frame by frame (see the module docstring); thread-safe."""

    KEEP = 32
    """Frames' runs remembered: more than the pump makes ahead, and the longest latency tracked, in frames."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._runs: dict[int, _Run] = {}
        self._injection: tuple[int, np.ndarray] | None = None
        self.faults = FaultPlan()
        """The AI Camera's faults in effect (``set_faults``)."""
        self._first_ns: int | None = None  # the first frame's start (``loaderfail`` counts from it)
        self._failure: DeviceError | None = None

    def set_faults(self, plan: FaultPlan) -> None:
        """Inject ``plan``'s AI Camera faults (``INSENSOR_FAULTS`` of ``rollcam.common.faults``) from now on."""
        with self._lock:
            self.faults = plan

    def _fail(self, frame: Frame, stats: Any) -> None:
        """Raise the stream's failure if it has failed, or fails at ``frame`` (counted once)."""
        plan = self.faults
        if self._failure is None and plan.insensor_faults:
            start = int(frame.timestamp_ns)
            if self._first_ns is None:
                self._first_ns = start
            if plan.loaderfail_ms is not None and start - self._first_ns >= plan.loaderfail_ms * 1_000_000:
                self._failure = LoaderFailure(f"{LOADER_FAILURE} (frame {frame.sequence})")
                if stats is not None:
                    stats.loader_failures += 1
            elif plan.fires("fetimeout", frame.sequence):
                self._failure = FrontendTimeout(f"{FRONTEND_TIMEOUT} (frame {frame.sequence})")
                if stats is not None:
                    stats.frontend_timeouts += 1
        if self._failure is not None:
            raise type(self._failure)(str(self._failure))

    def _place(self, spec: CameraSpec, frame: Frame, latency_ns: int, stats: Any) -> _Run:
        seq, start = frame.sequence, int(frame.timestamp_ns)
        run = self._runs.get(seq)
        if run is not None and run.start_ns == start:
            return run
        # A frame (re)made at seq invalidates the runs made ahead after it; the last KEEP frames made are kept
        # (however many the device skipped between them, so a result still rides on the next frame made).
        self._runs = {k: self._runs[k] for k in sorted(k for k in self._runs if k < seq)[-(self.KEEP - 1):]}
        input_ns = frame_end_ns(spec, start)
        busy = max((r.done_ns for r in self._runs.values() if r.done_ns is not None), default=None)
        # The window starts at the input of the frame made before this one: a frame the device skipped was
        # never delivered, so the results due on it ride on the next frame made instead of being lost.
        before = self._runs[max(self._runs)] if self._runs else None
        window = before.input_ns if before is not None else input_ns - spec.settings.timing.frame_period_ns
        accepted = busy is None or busy <= input_ns
        run = _Run(start, input_ns, input_ns + latency_ns if accepted else None, window)
        self._runs[seq] = run
        taken = self._injection is not None and seq >= self._injection[0]
        if taken:  # the comparison frame: its input is the injected tensor, if the accelerator takes it
            if accepted and seq == self._injection[0]:
                run.injected = self._injection[1]
            self._injection = None
        if stats is not None:
            if accepted:
                stats.insensor_runs += 1
            else:
                stats.insensor_skipped += 1
            if taken:
                stats.insensor_injected += run.injected is not None
                stats.insensor_injections_missed += run.injected is None
        return run

    def inject(self, spec: CameraSpec, tensor: np.ndarray | bytes, seq: int = 0) -> int:
        """Put ``tensor`` (``spec``'s input tensor format, flat, padded or not) in the place of the input of frame
        ``seq`` or, if that one is made already, the next to be made; returns that frame's sequence number (the
        comparison frame; ``FirmwareCamera.inject`` names its next frame and makes sure it is made).
        ``InjectionBusy`` while an earlier tensor waits; ConfigError when the network takes no input tensor;
        ValueError when the size is wrong."""
        cfg = spec.insensor
        if cfg is None or cfg.tensor is None:
            raise ConfigError("tensor injection needs an in-sensor network with an input tensor (insensor=SPEC and "
                              "insensor_tensor=WxH...)")
        planes = cfg.tensor.planes(tensor)
        padded = np.zeros((3, cfg.tensor.padded_size[1], cfg.tensor.padded_size[0]), np.uint8)
        padded[:, : planes.shape[1], : planes.shape[2]] = planes
        with self._lock:
            if self._injection is not None:
                raise InjectionBusy(f"an injected tensor still waits for frame {self._injection[0]}")
            seq = max(seq, max(self._runs) + 1 if self._runs else 0)
            self._injection = (seq, padded.view(cfg.tensor.dtype).ravel())
            return seq

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
        tensor: np.ndarray | None = None
        if cfg.tensor is not None:
            tensor, image, place = tensor_input(cfg, spec, frame)
            bits = 8
        else:
            image, bits, k = network_input(cfg, spec, frame, samples)
            x, y, _, _ = roi_in(cfg.roi, (frame.width, frame.height), even=cfg.input == "raw")
            place = (k, k, x, y)
        macs = int(net.macs(image.shape[1], image.shape[0]))
        with self._lock:
            self._fail(frame, stats)
            dnn_us = self.faults.dnn_us
            latency_ns = cfg.accel.latency_ns(macs) if dnn_us is None else dnn_us * 1000
            run = self._place(spec, frame, latency_ns, stats)
            todo = run.done_ns is not None and frame.shutter not in run.results
        if todo:  # the network runs off the lock: other transports' frames are not held up by it
            if run.injected is not None and cfg.tensor is not None:
                tensor, image = run.injected, cfg.tensor.picture_bgr(run.injected)
            result = self._infer(net, cfg, frame, run, image, bits, place, macs, tensor, run.injected is not None)
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
    def _infer(net: Network, cfg: InSensorConfig, frame: Frame, run: _Run, image: np.ndarray, bits: int,
               place: Place, macs: int, tensor: np.ndarray | None, injected: bool) -> InSensorResult:
        out = net.run(image, bits)
        sx, sy, x, y = place
        boxes = (np.asarray(out.boxes, np.float64).reshape(-1, 4) * [sx, sy, sx, sy] + [x, y, x, y]).astype(np.float32)
        assert run.done_ns is not None
        return InSensorResult(seq=frame.sequence, boxes=boxes, scores=out.scores, classes=out.classes,
                              timestamp_ns=int(frame.timestamp_ns), line_time_ns=int(frame.line_time_ns),
                              readout=frame.readout.value, exposure_ns=int(frame.exposure_ns),
                              input_ns=run.input_ns, done_ns=run.done_ns, input=str(cfg.input),
                              input_size=(int(image.shape[1]), int(image.shape[0])), macs=macs, network=net.name,
                              tensors=tuple((n, np.asarray(t)) for n, t in out.tensors), input_tensor=tensor,
                              injected=injected)

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
            self._injection = None
            self._first_ns, self._failure = None, None


def stream_ledger(spec: CameraSpec, stage: InSensorStage | None = None) -> Any:
    """``rollcam.firmware.ledger.ledger`` of ``spec``'s stream, with the in-sensor network's MACs at its binned
    input and the output of its latest result (from ``stage``; none yet: no detections or tensors counted)."""
    from .ledger import ledger

    cfg = spec.insensor
    if cfg is None:
        return ledger(spec)
    _, _, w, h = roi_in(cfg.roi, spec.size, even=cfg.input == "raw")
    k = bin_factor((w, h), cfg.max_size)
    w, h = (cfg.tensor.width, cfg.tensor.height) if cfg.tensor is not None else (w // k, h // k)
    macs = int(load_network(cfg.network).macs(w, h))
    latest = stage.latest() if stage is not None else None
    if latest is None:
        return ledger(spec, macs=macs)
    return ledger(spec, detections=len(latest), tensor_bytes=latest.tensor_bytes(), macs=macs)
