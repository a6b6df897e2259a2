"""Pixels of the emulated camera: the SyntheticCamera of a spec, test patterns, processed-format encoding.

``Imager`` keeps one ``SyntheticCamera`` for the current ``CameraSpec`` (rebuilt only when a setting that
changes pixels does) and makes frame ``seq`` from a start time it is given: the camera holds no clock.
Flips happen in one place, the SyntheticCamera's readout (a vertical flip of a row readout scans the
scene bottom-up, and a raw stream's Bayer order follows the flips as the sensor's does).

A raw format is the sensor model's output (EMVA noise, fixed patterns keyed by the serial number, temporal
noise by frame sequence, the ADC and the raw layout). A processed format is a BGR picture: the sensor
model's preview ISP when physics is on (the default for every format but BGR3), else the clean render; the
lens (``spec.lens``: vignetting, blur) acts inside the SyntheticCamera on linear radiance, for every format;
``finish`` runs the ISP's last steps on a processed picture (``picture_steps``: sharpening, JPEG), and
``encode`` turns it into the processed layout (YUYV, NV12, MJPG at ``mjpeg_quality``, ...); transports
encode it to their wire formats. A test pattern in a raw format is the BGR pattern sampled through the colour filter
(``rollcam.sim.formats.mosaic``) at full scale of the format's bits, without noise or black level.

``warm`` makes the first frame of a new kind of programming once, before a device's clock starts: the render
and sensor kernels are compiled by numba on first use (about 100 s of CPU time on a cold cache, more than a client's
DQBUF or HTTP timeout), and a real-time stream must not open by waiting for that.
"""

from __future__ import annotations

import contextlib
import dataclasses
import threading
from collections.abc import Callable

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.common.values import JPEG_QUALITY
from rollcam.sim import formats as sf
from rollcam.sim.codecs import codec
from rollcam.sim.frame import Frame
from rollcam.sim.picture import PictureSteps
from rollcam.sim.synthetic import SyntheticCamera

from .imu import FrameImu, with_imu
from .patterns import render_pattern
from .spec import CameraSpec, scene_of

_AFTER_RENDER = ("test_pattern", "picture")  # fields that change frames, not the SyntheticCamera
_WARM_KINDS: set[tuple] = set()  # process-wide, as numba's compiled kernels are


def kernel_kind(spec: CameraSpec) -> tuple:
    """What decides which compiled kernels a spec's frames run (the path through renderer, sensor model and
    packing), leaving out values that only change numbers: size, timing, exposure, gain, seeds."""
    return (spec.sensor.name, spec.pixel_format, spec.uses_physics, spec.blur_px > 0, spec.ego_blur,
            spec.noise, spec.hflip, spec.vflip, spec.shutter, spec.readout, spec.scene,
            spec.test_pattern != "none", spec.imu is not None, spec.rs_correct, spec.lens.on,
            picture_steps(spec).on)


def warm(spec: CameraSpec, imager: Imager | None = None) -> None:
    """Compile what ``spec``'s frames need, once per kind (``kernel_kind``) and process: render one frame and
    throw it away (frames are a function of spec, sequence and start, so none changes). ``imager``: the
    device's own, whose camera keeps the static layers it built; default a throwaway one, so frames being
    made meanwhile do not wait for it."""
    kind = kernel_kind(spec)
    if kind not in _WARM_KINDS:
        (imager or Imager()).render(spec, 0, 0)
        _WARM_KINDS.add(kind)


def warm_ahead(make: Callable[[], CameraSpec]) -> None:
    """``warm`` the spec ``make()`` builds, ahead of the change that commits it (outside the device's lock, so
    frames being made meanwhile do not wait); a spec that does not build is left for that change to refuse."""
    with contextlib.suppress(ConfigError):
        warm(make())


def synthetic_camera(spec: CameraSpec) -> SyntheticCamera:
    """The SyntheticCamera that renders ``spec``'s frames (raw samples, or a BGR picture for processed
    formats)."""
    fourcc = spec.pixel_format if spec.raw else "BGR3"
    return SyntheticCamera(spec.sensor, scene_of(spec), spec.camera, settings=spec.settings, pixel_format=fourcc,
                           physics=spec.uses_physics, blur_px=spec.blur_px or None, ego_path=spec.ego_blur == "path",
                           noise=spec.noise,
                           serial=spec.serial, noise_seed=spec.noise_seed, hflip=spec.hflip, vflip=spec.vflip,
                           optics=spec.lens, defects=spec.defects, mount=(*spec.mount_m, spec.mount_yaw_deg))


class Imager:
    """Makes a spec's frames; rebuilds its SyntheticCamera only when the pixels' programming changes."""

    def __init__(self) -> None:
        self._cached: tuple[CameraSpec, SyntheticCamera] | None = None
        # One frame at a time: the renderer's scratch buffers are shared, and two transports (HTTP's pump,
        # UVC's render-ahead) may ask for frames at once.
        self._render_lock = threading.Lock()
        self.imu = FrameImu()

    def camera(self, spec: CameraSpec) -> SyntheticCamera:
        """The SyntheticCamera for ``spec``."""
        cached = self._cached
        if cached is not None and cached[0] is spec:
            return cached[1]
        cam = cached[1] if cached is not None and _same_pixels(cached[0], spec) else synthetic_camera(spec)
        self._cached = (spec, cam)
        return cam

    def render(self, spec: CameraSpec, seq: int, start_ns: int, shutter: str | None = None) -> Frame:
        """Frame ``seq`` of ``spec`` exposed from device time ``start_ns`` (optionally under the other shutter)."""
        return self.render_samples(spec, seq, start_ns, shutter)[0]

    def render_samples(self, spec: CameraSpec, seq: int, start_ns: int, shutter: str | None = None
                       ) -> tuple[Frame, np.ndarray | None]:
        """``render``'s frame and the sensor's ADC samples behind it (uint16 H x W, output orientation; the test
        pattern's mosaic when one is on; None without the sensor model), for the in-sensor network."""
        with self._render_lock:
            cam = self.camera(spec)
            cam.last_samples = None
            frame = cam.render(seq, start_ns, shutter)
            samples = cam.last_samples
        if spec.imu is not None:
            frame = with_imu(frame, spec, cam.camera, self.imu, seq, start_ns)
        pattern = spec.test_pattern
        meta = {**frame.meta, "bayer_order": spec.bayer_order, "test_pattern": pattern,
                "pixel_format": spec.output_format}
        if pattern == "none":
            return finish(dataclasses.replace(frame, meta=meta), spec), samples
        image = render_pattern(pattern, frame.width, frame.height)
        bits = spec.sensor.bit_depth
        dn = sf.mosaic(image, spec.bayer_order).astype(np.uint16) << (bits - 8)  # hwconfig: 8..16 bits
        if spec.raw:
            data = codec(frame.format).encode(dn, sample_bits=bits)
            return dataclasses.replace(frame, data=data, objects=(), meta=meta), dn
        return finish(dataclasses.replace(frame, data=image, objects=(), meta=meta), spec), dn


def picture_steps(spec: CameraSpec) -> PictureSteps:
    """The ISP's last steps a frame of ``spec`` goes through: ``spec.picture``, none for raw formats (they bypass
    the ISP) and no JPEG round trip for MJPG, whose encoder is the compression (``mjpeg_quality``)."""
    if spec.raw:
        return PictureSteps()
    return dataclasses.replace(spec.picture, jpeg_quality=0) if spec.pixel_format == "MJPG" else spec.picture


def mjpeg_quality(spec: CameraSpec) -> int:
    """The quality an MJPG stream of ``spec`` is encoded at: its ``jpeg_quality``, else the default."""
    return spec.picture.jpeg_quality or JPEG_QUALITY


def finish(frame: Frame, spec: CameraSpec) -> Frame:
    """A processed frame through the ISP's last steps (``picture_steps``: sharpening, then the JPEG its encoder
    leaves), after every other step of the picture (the gyro correction included); raw frames and frames
    without a step on are returned as they are."""
    steps = picture_steps(spec)
    if not steps.on or not frame.data.size:
        return frame
    return dataclasses.replace(frame, data=steps.apply(frame.data), meta={**frame.meta, "isp": steps.info()})


def encode(frame: Frame, spec: CameraSpec) -> Frame:
    """A device frame in ``spec``'s processed format (raw frames and BGR3 are returned as they are; MJPG at
    ``mjpeg_quality``)."""
    fourcc = spec.pixel_format
    if spec.raw or frame.format == fourcc or not frame.data.size:  # no data: metadata-only mode
        return frame
    return dataclasses.replace(frame, data=codec(fourcc).encode(frame.data, quality=mjpeg_quality(spec)),
                               format=fourcc)


def _same_pixels(a: CameraSpec, b: CameraSpec) -> bool:
    """True when ``a`` and ``b`` differ at most in fields applied after the render (test pattern, ISP steps)."""
    if a.sensor is not b.sensor:
        return False
    return dataclasses.replace(a, **{k: getattr(b, k) for k in _AFTER_RENDER}) == b
