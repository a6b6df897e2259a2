"""``file:PATH[?fps=..&line_time_ns=..|sensor=..&method=..&out_fps=..&readout=..&frames=..]`` -- recorded footage.

PATH is a video or a folder of frames (``rollcam.sim.footage.Footage``; a folder needs ``fps=``). Without a
line time the source replays the footage as global-shutter Frames (line time 0, timestamps from the
footage's frame rate). With ``line_time_ns=T`` (integer ns per line) or ``sensor=NAME`` (that sensor's line
timing spread over the footage's lines, as ``emu:NAME?size=WxH`` would read them) it composes rolling-shutter
Frames as the original study did (``compose_stream``): line k of RS frame n is the footage at
``n / out_fps + k * T``, taken from the frame at that instant or synthesised between frames by ``method``
(nearest | linear | flow). Composed frames carry their row times; ``read_pair()`` gives the footage frame at
the RS frame's start beside the composed frame.

With ``labels=PATH`` (per-frame labels of the footage: instance masks, COCO JSON, MOT text or YOLO files,
``rollcam.sim.label_formats``; ``label_format=`` when the path does not tell) frames carry ground truth: a GS
frame its footage frame's objects, an RS frame the labels composed line by line from the same footage frames as
its image (``rollcam.sim.footage_labels``: exact from masks, within a stated bound from boxes). Without labels,
``objects=None``.

Options: ``fps`` (footage rate; a video's container rate by default), ``line_time_ns`` or ``sensor``,
``method`` (nearest), ``out_fps`` (the sensor's frame rate, or 30), ``readout`` (the sensor's, or
top_to_bottom), ``frames`` (stop after N frames), ``start`` (begin at footage frame N, or composed frame N),
``labels`` and ``label_format``, ``flow_preset`` and ``flow_margin_px`` (flow only).
Frames are BGR like every rollcam source (footage decodes to RGB; ``.npy`` frames are taken as RGB).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError, SourceError
from rollcam.sim.compose import METHODS, ComposedFrame, compose_stream, line_sources
from rollcam.sim.footage import Footage, as_fps
from rollcam.sim.footage_labels import LabelTrack, compose_truth, frame_truth
from rollcam.sim.frame import Frame, ObjectTruth
from rollcam.sim.hwconfig import load_sensor
from rollcam.sim.label_formats import load_labels
from rollcam.sim.synthetic import resolve_settings
from rollcam.sim.timing import NS_PER_S, LineTiming, Readout, line_sample_times_ns

from .base import CameraSource, SourceURI, non_negative_int, positive_int

OPTIONS = {"fps", "line_time_ns", "sensor", "method", "out_fps", "readout", "frames", "flow_preset",
           "flow_margin_px", "labels", "label_format", "start"}
ROLLING_ONLY = ("method", "out_fps", "readout", "flow_preset", "flow_margin_px")
DEFAULT_OUT_FPS = 30
_SNAP_NS = 1  # compose's default: absorbs the ns rounding of the footage and line clocks


def _pixel_format(frame: np.ndarray) -> str:
    """The fourcc of footage frames once colour is BGR: BGR3, GREY or 'Y16 '."""
    if frame.ndim == 3 and frame.shape[2] in (3, 4) and frame.dtype == np.uint8:
        return "BGR3"
    if frame.ndim == 2 and frame.dtype == np.uint8:
        return "GREY"
    if frame.ndim == 2 and frame.dtype == np.uint16:
        return "Y16 "
    raise ConfigError(f"footage frames of shape {frame.shape!r} and dtype {frame.dtype} have no pixel format "
                      "(need 8-bit colour or 8/16-bit grey)")


def to_bgr(frame: np.ndarray) -> np.ndarray:
    """A writable BGR copy of an RGB(A) footage frame (alpha dropped); grey frames are copied as they are."""
    if frame.ndim == 3:
        return np.ascontiguousarray(frame[..., 2::-1])
    return frame.copy()


def _open_labels(uri: SourceURI, fp: Footage) -> LabelTrack | None:
    """Per-frame labels (``labels=PATH``, ``label_format=``), checked against the footage's frames and size."""
    path = uri.get("labels", str)
    fmt = uri.get("label_format", str, "auto")
    if path is None:
        if "label_format" in uri.options:
            raise SourceError(f"source {uri.uri!r}: label_format= needs labels=PATH")
        return None
    try:
        labels = load_labels(path, fmt, n_frames=len(fp), size=(fp.width, fp.height), frame_names=fp.frame_names)
        labels[0]  # a first frame that does not parse fails here, not mid-stream
    except (SourceError, ConfigError) as exc:
        raise SourceError(f"source {uri.uri!r}: option labels={path!r}: {exc}") from None
    return labels


def nearest_frame(fp: Footage, t_ns: int) -> int:
    """The footage frame nearest ``t_ns`` (ties to the earlier), within the footage."""
    t = min(max(t_ns, fp.span_ns[0]), fp.span_ns[1])
    a = int(fp.index_at_or_before_ns(np.array([t]))[0])
    return a + 1 if a + 1 < len(fp) and fp.time_ns(a + 1) - t < t - fp.time_ns(a) else a


def _whole_frames(fp: Footage, last_line_ns: int, period_ns: Fraction, start_of: Callable[[int], int]) -> int:
    """How many composed frames (starting ``start_of(n)``, lasting ``last_line_ns``) fit in the footage's span."""
    end = fp.span_ns[1] + _SNAP_NS - last_line_ns
    n = int(end // period_ns) + 1 if end >= 0 else 0
    # Frame starts are rounded (compose_stream's closed forms): settle the last one exactly.
    while n > 0 and start_of(n - 1) > end:
        n -= 1
    while start_of(n) <= end:
        n += 1
    return n


class FileSource(CameraSource):
    """Footage replayed as GS Frames, or composed into RS Frames when given a line time."""

    def __init__(self, uri: SourceURI) -> None:
        self.uri = uri.uri
        uri.take(set(), OPTIONS)
        if not uri.target:
            raise SourceError(f"source {uri.uri!r}: name a video or a folder of frames, e.g. file:clip.mp4")
        self.path = Path(uri.target)
        self.limit: int | None = uri.get("frames", positive_int)
        self.start: int = uri.get("start", non_negative_int, 0)
        line_time_ns = uri.get("line_time_ns", positive_int)
        sensor_name = uri.get("sensor", str)
        if line_time_ns is not None and sensor_name is not None:
            raise SourceError(f"source {uri.uri!r}: give line_time_ns= or sensor=, not both")
        self.rolling = line_time_ns is not None or sensor_name is not None
        misplaced = [k for k in ROLLING_ONLY if k in uri.options] if not self.rolling else []
        if misplaced:
            raise SourceError(f"source {uri.uri!r}: option(s) {misplaced} apply only to composed rolling-shutter "
                              "frames; add line_time_ns= or sensor=")
        self.method = uri.get("method", str, "nearest")
        if self.method not in METHODS:
            raise SourceError(f"source {uri.uri!r}: method {self.method!r} is not one of {list(METHODS)}")
        fps = uri.get("fps", str)
        try:
            self.footage = Footage(self.path, fps)
        except ConfigError as exc:
            raise SourceError(f"source {uri.uri!r}: option fps={fps!r} is invalid ({exc})") from None
        except SourceError as exc:
            raise SourceError(f"source {uri.uri!r}: {exc}") from None
        self.index = 0
        self.labels: LabelTrack | None = None
        try:
            self.format = _pixel_format(self.footage[0])
            self.labels = _open_labels(uri, self.footage)
            self._stream: Iterator[ComposedFrame] | None = None
            self.timing: LineTiming | None = None
            self.out_fps: Fraction | None = None
            self.readout = Readout.TOP_TO_BOTTOM
            if self.rolling:
                self._setup_rolling(uri, line_time_ns, sensor_name)
        except ConfigError as exc:
            self.footage.close()
            raise SourceError(f"source {uri.uri!r}: {exc}") from None
        except SourceError:
            self.footage.close()
            raise
        self.supports_pairs = self.rolling

    def _setup_rolling(self, uri: SourceURI, line_time_ns: int | None, sensor_name: str | None) -> None:
        """Line timing, output rate and readout of the composed stream; footage must cover one RS frame."""
        fp = self.footage
        readout_opt = uri.get("readout", Readout.parse)
        out_fps_opt = uri.options.get("out_fps")
        try:
            out_fps = None if out_fps_opt is None else as_fps(out_fps_opt, "out_fps")
        except ConfigError as exc:
            raise SourceError(f"source {uri.uri!r}: option out_fps={out_fps_opt!r} is invalid ({exc})") from None
        if sensor_name is not None:
            try:
                sensor = load_sensor(sensor_name)
            except ConfigError as exc:
                raise SourceError(f"source {uri.uri!r}: option sensor={sensor_name!r}: {exc}") from None
            # The sensor's readout time spread over the footage's lines (its own mode when the size matches).
            settings = resolve_settings(sensor, size=(fp.width, fp.height), readout=readout_opt)
            timing, readout = settings.timing, settings.readout
        else:
            assert line_time_ns is not None
            readout = readout_opt or Readout.TOP_TO_BOTTOM
            n = fp.width if readout.by_column else fp.height
            timing = LineTiming(NS_PER_S, line_time_ns, n)  # offsets k * T ns exactly, no blanking
            out_fps = out_fps or Fraction(DEFAULT_OUT_FPS)
        n_lines = fp.width if readout.by_column else fp.height
        period = Fraction(NS_PER_S) / out_fps if out_fps is not None else Fraction(timing.frame_period_ns)
        readout_ns = int(timing.line_offset_ns(n_lines))
        if readout_ns > period:
            raise SourceError(
                f"source {uri.uri!r}: {n_lines} lines of {timing.line_time_ns} ns take {readout_ns} ns, longer "
                f"than the frame period {float(period):.0f} ns at {float(NS_PER_S / period):g} fps")
        first = line_sample_times_ns(0, n_lines, timing, readout)
        span_end = fp.span_ns[1]
        if int(first.max()) > span_end + _SNAP_NS:
            raise SourceError(
                f"source {uri.uri!r}: footage is too short for one rolling-shutter frame: {len(fp)} frames at "
                f"{float(fp.fps):g} fps span {span_end} ns, one frame's readout needs {int(first.max())} ns")
        self.timing, self.out_fps, self.readout = timing, out_fps, readout
        self._stream = iter(compose_stream(
            fp, timing, readout, fps=out_fps, method=self.method, snap_ns=_SNAP_NS,
            flow_preset=uri.get("flow_preset", str, "medium"),
            flow_margin_px=uri.get("flow_margin_px", non_negative_int), first_frame=self.start,
        ))

    # ---------------------------------------------------------------------------------------- frames
    def _done(self) -> bool:
        return self.limit is not None and self.index >= self.limit

    def _global_frame(self, k: int, sequence: int) -> Frame:
        """Footage frame ``k`` as a GS Frame."""
        t = self.footage.time_ns(k)
        n_lines = self.footage.height
        objects = None if self.labels is None else frame_truth(self.labels, k)
        return Frame(data=to_bgr(self.footage[k]), format=self.format, sequence=sequence, timestamp_ns=t,
                     line_time_ns=0, readout=Readout.TOP_TO_BOTTOM, exposure_ns=0, shutter="global",
                     row_times_ns=np.full(n_lines, t, np.int64), objects=objects,
                     meta={"source": str(self.path), "footage_index": k})

    def _rolling_truth(self, composed: ComposedFrame) -> tuple[ObjectTruth, ...] | None:
        """RS labels composed from the footage's labels with the same line sources as the image."""
        if self.labels is None:
            return None
        src = line_sources(self.footage, composed.line_times_ns, _SNAP_NS)
        blended = None if self.method == "nearest" else ~src.exact
        return compose_truth(self.labels, src, nearest_frame(self.footage, composed.t_start_ns),
                             by_column=self.readout.by_column, blended=blended)

    def _next_rolling(self) -> Frame | None:
        assert self._stream is not None and self.timing is not None
        try:
            composed = next(self._stream)
        except StopIteration:
            return None
        return Frame(data=to_bgr(composed.data), format=self.format, sequence=composed.index,
                     timestamp_ns=composed.t_start_ns, line_time_ns=self.timing.line_time_ns, readout=self.readout,
                     exposure_ns=0, shutter="rolling", row_times_ns=composed.line_times_ns,
                     objects=self._rolling_truth(composed),
                     meta={"source": str(self.path), "method": self.method,
                           "footage_fps": str(self.footage.fps)})

    def read(self) -> Frame | None:
        """The next frame (GS replay or composed RS), or None at the end of the footage or after ``frames=N``."""
        self._check_open()
        if self._done():
            return None
        if self.rolling:
            frame = self._next_rolling()
        elif self.start + self.index < len(self.footage):
            frame = self._global_frame(self.start + self.index, self.index)
        else:
            frame = None
        if frame is not None:
            self.index += 1
        return frame

    def read_pair(self) -> tuple[Frame, Frame] | None:
        """(footage frame nearest the RS frame's start, as GS; the composed RS frame), or None at the end."""
        if not self.rolling:
            return super().read_pair()
        self._check_open()
        if self._done():
            return None
        rs = self._next_rolling()
        if rs is None:
            return None
        self.index += 1
        return self._global_frame(nearest_frame(self.footage, rs.timestamp_ns), rs.sequence), rs

    def composed_frames(self) -> int:
        """How many RS frames the footage holds whole (every line's time in its span); arithmetic, no pixels."""
        if not self.rolling:
            raise SourceError(f"source {self.uri!r}: composes no rolling-shutter frames (no line_time_ns= or sensor=)")
        assert self.timing is not None
        n_lines = self.footage.width if self.readout.by_column else self.footage.height
        last_line_ns = int(line_sample_times_ns(0, n_lines, self.timing, self.readout).max())
        period = (Fraction(self.timing.frame_period_pck * NS_PER_S, self.timing.pixel_rate_hz)
                  if self.out_fps is None else Fraction(NS_PER_S) / self.out_fps)
        return _whole_frames(self.footage, last_line_ns, period, self.frame_start_ns)

    def frame_start_ns(self, n: int) -> int:
        """Start of composed frame ``n`` (``compose_stream``'s rule with start_ns 0)."""
        assert self.timing is not None
        if self.out_fps is None:
            return self.timing.frame_start_ns(n)
        num, den = self.out_fps.numerator, self.out_fps.denominator
        return (2 * n * NS_PER_S * den + num) // (2 * num)

    def _close(self) -> None:
        """Release the footage."""
        self.footage.close()

    def info(self) -> dict[str, Any]:
        """Footage and, when composing, the RS timing as plain data."""
        fp = self.footage
        out: dict[str, Any] = {"uri": self.uri, "path": str(self.path), "footage_frames": len(fp),
                               "footage_fps": float(fp.fps), "width": fp.width, "height": fp.height,
                               "format": self.format, "shutter": "rolling" if self.rolling else "global"}
        if self.rolling:
            assert self.timing is not None
            out.update(line_time_ns=self.timing.line_time_ns, readout=self.readout.value, method=self.method,
                       fps=float(self.out_fps) if self.out_fps is not None else self.timing.fps)
        return out

    def __repr__(self) -> str:
        kind = f"rolling {self.method}" if self.rolling else "global"
        return f"FileSource({str(self.path)!r}, {kind}, frame {self.index}{', closed' if self.closed else ''})"


def open_source(uri: SourceURI) -> FileSource:
    """Scheme entry point for ``file:``."""
    return FileSource(uri)
