"""Pixels of the firmware camera: a cached SyntheticCamera per programming, test patterns, flips.

A vertical flip (a horizontal one for column readout) renders the opposite readout direction and mirrors
the image, so the first line out of the sensor is still the first line read, as on the real part; the
ground-truth boxes are mirrored with the pixels.

Processed formats (YUYV, MJPG, ...) start from a plain BGR render. A raw format goes through the sensor
model instead (``SyntheticCamera(pixel_format=...)``: EMVA noise on, fixed patterns keyed by the device's
serial number, temporal noise by frame sequence, the ADC and the raw layout), read out with the flips so the
Bayer order and fourcc follow them. Motion blur (integration over each line's exposure) costs several
renders per line, so real-time devices default to ``blur_px=0`` (each line sampled at mid-exposure); a
positive bound turns it on. A test pattern in a raw format is the BGR pattern sampled through the colour
filter (``rollcam.sim.formats.mosaic``) at full scale of the format's bits, without noise or black level.
"""

from __future__ import annotations

import dataclasses
import threading
from typing import Any

import numpy as np
from rollcam.sim import formats as sf
from rollcam.sim.codecs import codec
from rollcam.sim.frame import Frame, ObjectTruth
from rollcam.sim.hwconfig import SensorConfig
from rollcam.sim.synthetic import SyntheticCamera
from rollcam.sim.timing import Readout

from .controls import SensorState
from .patterns import render_pattern
from .scene import build_scene
from .scheduler import FrameSchedule

_OPPOSITE = {Readout.TOP_TO_BOTTOM: Readout.BOTTOM_TO_TOP, Readout.BOTTOM_TO_TOP: Readout.TOP_TO_BOTTOM,
             Readout.LEFT_TO_RIGHT: Readout.RIGHT_TO_LEFT, Readout.RIGHT_TO_LEFT: Readout.LEFT_TO_RIGHT}


class Imager:
    """Makes a sensor's frames for a programmed state; rebuilds its SyntheticCamera only when that changes."""

    def __init__(self, sensor: SensorConfig, *, serial: str = "0", blur_px: float = 0.0) -> None:
        self.sensor = sensor
        self.serial = serial
        self.blur_px = blur_px
        self._cached: tuple[tuple, SyntheticCamera] | None = None
        # One frame at a time: rendering sets the camera's clock for the frame and uses the renderer's scratch
        # buffers, and two transports (HTTP's pump, UVC's render-ahead) may ask for frames at once.
        self._render_lock = threading.Lock()

    def camera(self, s: SensorState, scene_options: dict[str, Any], raw_fourcc: str | None = None
               ) -> SyntheticCamera:
        """The SyntheticCamera for this programming (mode, frame/line length, exposure, gain, shutter, scene,
        and for a raw format, given unflipped as the sensor lists it, the format and the flips)."""
        readout = self.sensor.readout
        line_flip = s.vflip if not readout.by_column else s.hflip
        flips = (s.hflip, s.vflip) if raw_fourcc else (line_flip,)
        key = (s.mode.name, s.frame_length_lines, s.line_length_pck, s.exposure_lines, s.gain, s.shutter,
               flips, raw_fourcc, self.blur_px, tuple(sorted(scene_options.items(), key=str)))
        if self._cached is None or self._cached[0] != key:
            mode = dataclasses.replace(s.mode, frame_length_lines=s.frame_length_lines,
                                       line_length_pck=s.line_length_pck)
            sensor = dataclasses.replace(self.sensor, modes=(mode,), default_mode=mode.name)
            scene = build_scene(scene_options, mode.width, mode.height)
            common = {"size": (mode.width, mode.height), "shutter": s.shutter, "gain": s.gain,
                      "exposure_ns": int(s.timing.line_offset_ns(s.exposure_lines))}
            if raw_fourcc:  # the sensor model reads the array flipped itself
                cam = SyntheticCamera(sensor, scene, 0, readout=readout, pixel_format=raw_fourcc,
                                      blur_px=self.blur_px or None, serial=self.serial, hflip=s.hflip,
                                      vflip=s.vflip, **common)
            else:
                cam = SyntheticCamera(sensor, scene, 0, readout=_OPPOSITE[readout] if line_flip else readout,
                                      **common)
            self._cached = (key, cam)
        return self._cached[1]

    def render(self, cam: SyntheticCamera, plan: Any, hflip: bool, vflip: bool, pattern: str,
               bayer_order: str) -> Frame:
        """Frame ``plan.seq`` (``plan``: a FramePlan) from ``cam``, with the test pattern and flips applied."""
        sched: FrameSchedule = plan.schedule
        with self._render_lock:
            if cam.pipeline is not None:
                return self._render_raw(cam, plan, pattern, bayer_order)
            cam.start_ns = sched.start_ns(plan.seq)  # frame 0 of a camera whose clock starts at this frame
            frame = cam.frame(0)
        meta = {**frame.meta, "bayer_order": bayer_order, "test_pattern": pattern}
        if pattern != "none":
            return dataclasses.replace(frame, data=render_pattern(pattern, frame.width, frame.height),
                                       sequence=plan.seq, objects=(), meta=meta)
        data, rows, objects = frame.data, frame.row_times_ns, frame.objects
        by_col = self.sensor.readout.by_column
        if hflip:
            data, objects = data[:, ::-1], _flip_boxes(objects, frame.width, None)
            rows = rows[::-1] if rows is not None and by_col else rows
        if vflip:
            data, objects = data[::-1], _flip_boxes(objects, None, frame.height)
            rows = rows[::-1] if rows is not None and not by_col else rows
        if hflip or vflip:
            data = np.ascontiguousarray(data)
        return dataclasses.replace(frame, data=data, row_times_ns=rows, objects=objects, sequence=plan.seq,
                                   readout=self.sensor.readout, meta=meta)

    def _render_raw(self, cam: SyntheticCamera, plan: Any, pattern: str, bayer_order: str) -> Frame:
        """A raw frame through the sensor model (flips already in the readout), or a mosaicked test pattern."""
        # Frame ``seq`` of a camera whose clock puts it at the schedule's start: temporal noise follows seq.
        seq = plan.seq
        cam.start_ns = plan.schedule.start_ns(seq) - cam.settings.timing.frame_start_ns(seq, 0)
        frame = cam.frame(seq)
        meta = {**frame.meta, "bayer_order": bayer_order, "test_pattern": pattern}
        if pattern == "none":
            return dataclasses.replace(frame, meta=meta)
        bits = self.sensor.bit_depth
        cfa = sf.mosaic(render_pattern(pattern, frame.width, frame.height), bayer_order)
        dn = cfa.astype(np.uint16) << (bits - 8)  # hwconfig holds bit_depth to 8..16
        return dataclasses.replace(frame, data=codec(frame.format).encode(dn, sample_bits=bits), objects=(),
                                   meta=meta)


def _flip_boxes(objects: tuple[ObjectTruth, ...] | None, width: int | None, height: int | None
                ) -> tuple[ObjectTruth, ...] | None:
    """Ground-truth boxes mirrored across the image width or height (whichever is given)."""
    if objects is None:
        return None

    def flip(b: tuple[float, float, float, float] | None) -> tuple[float, float, float, float] | None:
        if b is None:
            return None
        x0, y0, x1, y1 = b
        return (width - x1, y0, width - x0, y1) if width is not None else (x0, height - y1, x1, height - y0)

    return tuple(dataclasses.replace(o, box_gs=flip(o.box_gs), box_rs=flip(o.box_rs)) for o in objects)
