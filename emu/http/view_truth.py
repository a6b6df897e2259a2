"""What the live view knows about each frame besides its pixels: timing, truth, row times, detections.

``FrameTap`` is a frame sink (a pump's, or any producer's ``on_frame(frame, plan)``). For each frame, while
someone watches, it keeps a ``FrameInfo`` (a few scalars and references: constant time on the device's
thread) in a small ring by sequence number; the page server turns it into JSON once, on its own thread, when
it sends that frame. Row times are kept as ticks (every ``n/8`` image lines, with their exact times) so the
page can draw a ruler without a thousand numbers a frame. An optional ``annotate(frame) -> [box, ...]`` (a
detector the host supplies: this layer knows no detector) runs on its own thread on the newest frame only;
frames that arrive while it works are skipped, so a slow detector lags and never holds up the device.
"""

from __future__ import annotations

import collections
import contextlib
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from rollcam.common.errors import DeviceError
from rollcam.common.lifecycle import Closeable, Stats, Worker
from rollcam.sim.frame import Frame, ObjectTruth
from rollcam.sim.timing import Readout

RING = 32  # frames whose info is kept: the encoder and the slowest client are never further behind
RULER_TICKS = 8
Annotate = Callable[[Frame], list[dict[str, Any]]]


@dataclass
class TapStats(Stats):
    """What the tap did: frames seen, ns spent on them (the device thread's cost), annotations made."""

    frames: int = 0
    tap_ns: int = 0
    annotated: int = 0
    annotate_errors: int = 0


@dataclass
class FrameInfo:
    """One frame's metadata and truth, as taken on the device's thread (no pixels: JSON is made later, once)."""

    seq: int
    timestamp_ns: int
    exposure_ns: int
    line_time_ns: int
    readout: Readout
    shutter: str
    size: tuple[int, int]
    format: str
    objects: tuple[ObjectTruth, ...] | None = field(repr=False)
    ticks: list[tuple[int, int]] = field(repr=False)
    _json: dict[str, Any] | None = field(default=None, repr=False)

    @classmethod
    def of(cls, f: Frame) -> FrameInfo:
        """The info of ``f`` (its pixels are not kept)."""
        return cls(f.sequence, int(f.timestamp_ns), int(f.exposure_ns), int(f.line_time_ns), f.readout, f.shutter,
                   (f.width, f.height), f.format.strip(), f.objects, ruler_ticks(f))

    def to_json(self) -> dict[str, Any]:
        """The page's per-frame record: timing, row ticks (line, ns after the first line read), objects."""
        if self._json is None:
            start = min((t for _, t in self.ticks), default=0)
            self._json = {
                "seq": self.seq, "timestamp_ns": str(self.timestamp_ns), "exposure_ns": self.exposure_ns,
                "line_time_ns": self.line_time_ns, "readout": self.readout.value, "shutter": self.shutter,
                "width": self.size[0], "height": self.size[1], "format": self.format,
                "by_column": self.readout.by_column, "rows": [[line, t - start] for line, t in self.ticks],
                "objects": None if self.objects is None else [o.to_json() for o in self.objects]}
        return self._json


def ruler_ticks(frame: Frame, n: int = RULER_TICKS) -> list[tuple[int, int]]:
    """``n + 1`` image lines spread over the frame with their sample times (int ns), for the row ruler."""
    times = frame.row_times_ns
    lines = frame.width if frame.readout.by_column else frame.height
    if times is None or len(times) != lines or lines == 0:
        return []
    picks = sorted({round(i * (lines - 1) / n) for i in range(n + 1)})
    return [(int(i), int(times[i])) for i in picks]


class FrameTap(Closeable):
    """A frame sink keeping ``FrameInfo`` for the page while ``watching()`` says someone is looking."""

    def __init__(self, watching: Callable[[], bool], annotate: Annotate | None = None,
                 clock: Callable[[], int] = time.perf_counter_ns) -> None:
        self.watching, self.annotate, self.clock = watching, annotate, clock
        self.stats = TapStats()
        self._ring: collections.OrderedDict[int, FrameInfo] = collections.OrderedDict()
        self._lock = threading.Lock()
        self._waiters: list[Callable[[Frame], None]] = []
        self.detections: dict[str, Any] | None = None  # the newest annotation: {"seq", "ms", "boxes"}
        self._todo: queue.Queue[Frame] = queue.Queue(maxsize=1)
        self._worker = Worker(self._annotate_loop, name="rollcam-view-annotate", wrap=DeviceError)
        if annotate is not None:
            self._worker.start()

    def on_band(self, frame: Frame, plan: Any, band: int, n_bands: int) -> None:
        """Bands are not shown separately."""

    def on_frame(self, frame: Frame, plan: Any = None) -> None:
        """Keep the frame's info (and give it to snapshot waiters and the annotator) when anyone watches."""
        with self._lock:
            waiters, self._waiters = self._waiters, []
        if not waiters and not self.watching():
            return
        t0 = self.clock()
        info = FrameInfo.of(frame)
        with self._lock:
            self._ring[frame.sequence] = info
            while len(self._ring) > RING:
                self._ring.popitem(last=False)
        for waiter in waiters:
            waiter(frame)
        if self.annotate is not None:
            _put_newest(self._todo, frame)
        self.stats.frames += 1
        self.stats.tap_ns += self.clock() - t0

    def info(self, seq: int) -> FrameInfo | None:
        """The info of frame ``seq`` while it is in the ring."""
        with self._lock:
            return self._ring.get(seq)

    def next_frame(self, callback: Callable[[Frame], None]) -> None:
        """Call ``callback(frame)`` with the next frame (on the producer's thread: it must not block)."""
        with self._lock:
            self._waiters.append(callback)

    def cancel(self, callback: Callable[[Frame], None]) -> None:
        """Forget a ``next_frame`` callback not yet called."""
        with self._lock:
            self._waiters = [w for w in self._waiters if w is not callback]

    def _annotate_loop(self) -> None:
        assert self.annotate is not None
        while not self._worker.stopping:
            try:
                frame = self._todo.get(timeout=0.2)
            except queue.Empty:
                continue
            t0 = time.perf_counter()
            try:
                boxes = self.annotate(frame)
            except Exception as exc:  # a detector failing on one frame says so on the page; the view goes on
                self.stats.annotate_errors += 1
                self.detections = {"seq": frame.sequence, "ms": 0.0, "boxes": [], "error": repr(exc)[:200]}
                continue
            self.stats.annotated += 1
            self.detections = {"seq": frame.sequence, "ms": round((time.perf_counter() - t0) * 1e3, 1),
                               "boxes": boxes}

    def _close(self) -> None:
        self._worker.close()


def _put_newest(q: queue.Queue[Frame], item: Frame) -> None:
    """Put ``item`` in a one-slot queue, dropping the older one waiting there."""
    with contextlib.suppress(queue.Empty):
        q.get_nowait()
    with contextlib.suppress(queue.Full):  # another put raced us: a frame as new as this one is waiting
        q.put_nowait(item)
