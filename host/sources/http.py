"""``http://HOST:PORT/PATH[#sensor=..&timeout=..&frames=..]`` -- an MJPEG stream (multipart/x-mixed-replace).

The URL (query included) goes to the server untouched; rollcam's own options ride in the fragment, which
HTTP clients never send. Each part's JPEG is decoded to BGR3 (the codec table's MJPEG decoder). Part headers fill
the Frame when the server sends them (the rollcam emulator does; mjpg-streamer sends ``X-Timestamp``):

| Part header | Frame field | Form |
| --- | --- | --- |
| ``X-Sequence`` | ``sequence`` | integer frame counter of the device |
| ``X-Timestamp-Ns`` | ``timestamp_ns`` | integer ns, device clock, first line's start of exposure |
| ``X-Timestamp`` | ``timestamp_ns`` | seconds (decimal), when ``X-Timestamp-Ns`` is absent |
| ``X-Exposure-Ns`` | ``exposure_ns`` | integer ns |
| ``X-Line-Time-Ns`` | ``line_time_ns`` | integer ns (0: global shutter) |
| ``X-Readout`` | ``readout`` | ``top_to_bottom`` etc. (as in hw_configs) |
| ``X-Shutter`` | ``shutter`` | ``rolling`` or ``global`` |
| ``X-Insensor`` | ``insensor`` | the camera's in-sensor results, a JSON list of ``InSensorResult.to_json()`` |

Without them: sequence counts parts received, the timestamp is the host's monotonic clock at arrival, and
the row timing comes from ``sensor=NAME`` (or is unknown). A line time from the headers wins over the
sensor's, except that when it equals the sensor's rounded line time the sensor's exact (sub-ns) row offsets
are kept: ``X-Line-Time-Ns`` is whole ns, so rows built from it alone drift from the true ones (imx219's
18,903.5 ns line by 0.5 ns a row). ``X-Shutter: rolling`` needs a line time (the header's or the sensor's);
an unknown shutter or readout, or a negative line time or exposure, is a ProtocolError naming the header.
Options: ``sensor``, ``timeout`` (seconds to connect and between parts, default 10), ``frames``,
``latest`` (a boolean, 1/on/true/yes: a thread reads the stream and ``read()`` returns the newest part,
dropping older ones, so a consumer slower than the stream, such as a detector, sees live frames instead of a
growing backlog; the count dropped goes into ``meta["dropped"]``; default off: every part, in order). An
option given twice in the fragment is refused, as in any query.

``probe()`` reads the first two frames ahead (``read()`` still returns them, in order) so that ``info()`` can
tell the size and the frame rate before the first read, as OpenCV's FFmpeg backend does when it opens a stream;
the rate comes from the parts' device timestamps (``X-Timestamp-Ns``/``X-Timestamp``), else it is FFmpeg's
25 fps for an MJPEG stream that states none.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections import deque
from collections.abc import Callable
from decimal import Decimal, InvalidOperation
from typing import Any, BinaryIO
from urllib.error import URLError
from urllib.parse import parse_qsl, urldefrag
from urllib.request import Request, urlopen

from rollcam.common.errors import DeviceError, DeviceNotFoundError, ProtocolError, SourceError
from rollcam.common.lifecycle import Closeable, Worker
from rollcam.common.values import parse_bool, parse_query
from rollcam.sim.codecs import codec
from rollcam.sim.frame import Frame
from rollcam.sim.timing import NS_PER_S, LineTiming, Readout, line_sample_times_ns

from .base import CameraSource, SourceURI, non_negative_int, positive_float, positive_int
from .rowtiming import FrameTimer

_JPEG = codec("MJPG")

OPTIONS = {"sensor", "timeout", "frames", "latest"}
UNSTATED_FPS = 25.0  # what FFmpeg (so cv2.VideoCapture) reports for an MJPEG stream without a rate
MAX_HEADER_LINES = 64
MAX_PART_BYTES = 64 << 20


def _seconds_to_ns(text: str) -> int:
    return int(Decimal(text) * 1_000_000_000)


SHUTTERS = ("rolling", "global")


def _shutter(text: str) -> str:
    value = text.strip().lower()
    if value not in SHUTTERS:
        raise ValueError(f"not one of {list(SHUTTERS)}")
    return value


def _insensor(text: str) -> tuple[Any, ...]:
    import json

    from rollcam.sim.insensor import InSensorResult

    try:
        return tuple(InSensorResult.from_json(d) for d in json.loads(text))
    except (KeyError, TypeError, AttributeError) as exc:
        raise ValueError(f"not a list of in-sensor results ({exc})") from None


PART_HEADERS: dict[str, tuple[str, Callable[[str], Any]]] = {
    "x-sequence": ("sequence", int),
    "x-timestamp-ns": ("timestamp_ns", int),
    "x-timestamp": ("timestamp_s", _seconds_to_ns),
    "x-exposure-ns": ("exposure_ns", non_negative_int),
    "x-line-time-ns": ("line_time_ns", non_negative_int),
    "x-readout": ("readout", Readout.parse),
    "x-shutter": ("shutter", _shutter),
    "x-insensor": ("insensor", _insensor),
}
"""Part header (lower case) -> (field, parser). ``timestamp_s`` is used only without ``timestamp_ns``."""


def boundary_of(content_type: str) -> bytes:
    """The multipart boundary named in a Content-Type header."""
    kind, _, params = content_type.partition(";")
    if kind.strip().lower() != "multipart/x-mixed-replace":
        raise ProtocolError(f"expected an MJPEG stream (multipart/x-mixed-replace), got Content-Type {content_type!r}")
    for key, value in parse_qsl(params.replace(";", "&").replace(" ", ""), keep_blank_values=True):
        if key.lower() == "boundary" and value:
            return value.strip('"').encode("latin-1")
    raise ProtocolError(f"Content-Type {content_type!r} names no boundary")


class MjpegParser:
    """Splits a multipart/x-mixed-replace byte stream into (headers, body) parts."""

    def __init__(self, stream: BinaryIO, boundary: bytes) -> None:
        self.stream = stream
        # Some servers put the leading dashes into the boundary parameter itself; accept both spellings.
        b = boundary[2:] if boundary.startswith(b"--") else boundary
        self.delimiters = {b"--" + b, b"----" + b, b}
        self._pending: bytes | None = None

    def _line(self) -> bytes | None:
        line = self.stream.readline(65536)
        return line if line else None

    def _is_delimiter(self, line: bytes) -> bool:
        s = line.strip()
        return s in self.delimiters or (s.endswith(b"--") and s[:-2] in self.delimiters)

    def next_part(self) -> tuple[dict[str, str], bytes] | None:
        """The next part, or None at the end of the stream."""
        line = self._pending
        self._pending = None
        while line is None or not self._is_delimiter(line):  # skip the preamble / CRLF before a delimiter
            line = self._line()
            if line is None:
                return None
        if line.strip().endswith(b"--") and line.strip()[:-2] in self.delimiters:
            return None  # closing delimiter
        headers: dict[str, str] = {}
        for _ in range(MAX_HEADER_LINES):
            line = self._line()
            if line is None:
                return None
            if not line.strip():
                break
            key, sep, value = line.decode("latin-1").partition(":")
            if not sep:
                raise ProtocolError(f"malformed MJPEG part header {line[:80]!r}")
            headers[key.strip().lower()] = value.strip()
        else:
            raise ProtocolError(f"MJPEG part has more than {MAX_HEADER_LINES} header lines")
        if "content-length" in headers:
            try:
                n = int(headers["content-length"])
            except ValueError:
                bad = headers["content-length"]
                raise ProtocolError(f"MJPEG part Content-Length {bad!r} is not a number") from None
            if not 0 <= n <= MAX_PART_BYTES:
                raise ProtocolError(f"MJPEG part Content-Length {n!r} is out of range")
            body = self.stream.read(n)
            if len(body) < n:
                return None
            return headers, body
        chunks: list[bytes] = []  # no length: the body runs to the next delimiter line
        size = 0
        while True:
            line = self._line()
            if line is None or self._is_delimiter(line):
                self._pending = line
                body = b"".join(chunks)
                return (headers, body[:-2] if body.endswith(b"\r\n") else body) if chunks or line else None
            size += len(line)
            if size > MAX_PART_BYTES:  # a server that never sends the next boundary must not grow us forever
                raise ProtocolError(f"MJPEG part without Content-Length runs past {MAX_PART_BYTES} bytes with no "
                                    "boundary")
            chunks.append(line)


def part_fields(headers: dict[str, str], uri: str) -> dict[str, Any]:
    """The Frame fields a part's headers carry (see PART_HEADERS); a malformed value is a ProtocolError."""
    out: dict[str, Any] = {}
    for name, (fld, parse) in PART_HEADERS.items():
        if name in headers:
            try:
                out[fld] = parse(headers[name])
            except (ValueError, InvalidOperation, ArithmeticError) as exc:
                raise ProtocolError(f"source {uri!r}: part header {name}={headers[name]!r} is invalid "
                                    f"({exc})") from None
    if "timestamp_s" in out:
        out.setdefault("timestamp_ns", out["timestamp_s"])
        del out["timestamp_s"]
    return out


class LatestPart(Closeable):
    """Reads parts on a thread and keeps only the newest (with its arrival time) for a slower consumer."""

    def __init__(self, next_part: Callable[[], tuple[dict[str, str], bytes] | None], clock: Callable[[], int]) -> None:
        self._next, self._clock = next_part, clock
        self._cond = threading.Condition()
        self._part: tuple[tuple[dict[str, str], bytes], int] | None = None
        self._done = False
        self.dropped = 0
        self._worker = Worker(self._run, name="mjpeg-reader")
        self._worker.start()

    def _run(self) -> None:
        try:
            while not self._worker.stopping and (part := self._next()) is not None:
                arrival = self._clock()
                with self._cond:
                    self.dropped += self._part is not None
                    self._part = (part, arrival)
                    self._cond.notify_all()
        finally:  # an error is kept by the worker and handed to the consumer by get()
            with self._cond:
                self._done = True
                self._cond.notify_all()

    def get(self, timeout_s: float) -> tuple[tuple[dict[str, str], bytes], int] | None:
        """The newest part not yet taken and its arrival time; None at the end of the stream."""
        with self._cond:
            if not self._cond.wait_for(lambda: self._part is not None or self._done, timeout_s):
                raise TimeoutError
            if self._part is not None:
                got, self._part = self._part, None
                return got
        self._worker.join()  # the reader has ended: re-raise what ended it, if anything did
        return None

    def _close(self) -> None:
        """Tell the reader to stop (the owner closes the connection it blocks on; it is not waited for)."""
        self._worker.stop()


class HttpMjpegSource(CameraSource):
    """Frames of an MJPEG-over-HTTP stream, with device timing from part headers where sent."""

    def __init__(self, uri: SourceURI, clock: Callable[[], int] = time.monotonic_ns) -> None:
        self.uri = uri.uri
        url, fragment = urldefrag(uri.uri)
        opts = SourceURI(uri.uri, uri.scheme, url, parse_query(fragment, f"source {uri.uri!r}", SourceError))
        opts.take(set(), OPTIONS)
        self.url, self.clock = url, clock
        self.timeout_s = opts.get("timeout", positive_float, 10.0)
        self.limit = opts.get("frames", positive_int)
        self.timer = FrameTimer(opts.get("sensor", str), uri.uri)
        latest = opts.get("latest", parse_bool, False)  # every option is checked before connecting
        self.index = 0  # frames returned by read()
        self._parts = 0  # parts decoded (read ahead by probe() included)
        self._ahead: deque[Frame] = deque()
        self._stamped = False
        self._stream_info: dict[str, Any] = {}
        try:
            self._response = urlopen(Request(url, headers={"User-Agent": "rollcam"}), timeout=self.timeout_s)
        except (URLError, OSError) as exc:
            raise DeviceNotFoundError(f"source {uri.uri!r}: cannot connect ({getattr(exc, 'reason', exc)}); is "
                                      "the stream running (e.g. 'rollcam emulate')?") from None
        try:
            self._parser = MjpegParser(self._response, boundary_of(self._response.headers.get("Content-Type", "")))
        except ProtocolError as exc:
            self._response.close()
            raise SourceError(f"source {uri.uri!r}: {exc}") from None
        self._latest = LatestPart(self._parser.next_part, clock) if latest else None

    def read(self) -> Frame | None:
        """The next decoded frame, or None when the server ends the stream (or after ``frames=N``)."""
        self._check_open()
        if self.limit is not None and self.index >= self.limit:
            return None
        frame = self._ahead.popleft() if self._ahead else self._next_frame()
        if frame is not None:
            self.index += 1
        return frame

    def probe(self) -> dict[str, Any]:
        """Width, height and fps of the stream, from its first frames (read ahead, not lost); empty when the
        stream ends before its first frame."""
        self._check_open()
        if not self._stream_info:
            want = 2 if self.limit is None or self.limit - self.index >= 2 else 1
            stamped = [self._stamped] * len(self._ahead)
            while len(self._ahead) < want and (frame := self._next_frame()) is not None:
                self._ahead.append(frame)
                stamped.append(self._stamped)
            if self._ahead:
                first = self._ahead[0]
                fps = _fps(*self._ahead) if len(self._ahead) == 2 and all(stamped) else UNSTATED_FPS
                self._stream_info = {"width": first.width, "height": first.height, "fps": fps}
        return dict(self._stream_info)

    def _next_frame(self) -> Frame | None:
        try:
            if self._latest is not None:
                got = self._latest.get(self.timeout_s)
                part, arrival_ns = got if got is not None else (None, 0)
            else:
                part = self._parser.next_part()
                arrival_ns = self.clock()
        except TimeoutError:
            raise DeviceError(f"source {self.uri!r}: no frame within {self.timeout_s:g} s") from None
        except OSError as exc:
            raise DeviceError(f"source {self.uri!r}: connection lost ({exc})") from None
        if part is None:
            return None
        headers, body = part
        try:
            image = _JPEG.decode(body)
        except ProtocolError:
            raise ProtocolError(f"source {self.uri!r}: part {self._parts} is not a decodable JPEG ({len(body)} bytes)"
                                ) from None
        fields = part_fields(headers, self.uri)
        fmt = "BGR3"
        seq = fields.get("sequence", self._parts)
        self._stamped = "timestamp_ns" in fields  # a device timestamp from the server, not the arrival time
        ts = fields.get("timestamp_ns", arrival_ns)
        frame = self.timer.frame(image, fmt, seq, ts, fields.get("exposure_ns", 0),
                                 meta={"arrival_ns": arrival_ns, "jpeg_bytes": len(body),
                                       **({"dropped": self._latest.dropped} if self._latest is not None else {})})
        if "line_time_ns" in fields or "shutter" in fields or "readout" in fields:
            frame = self._with_header_timing(frame, fields)
        if "insensor" in fields:
            frame = dataclasses.replace(frame, insensor=fields["insensor"])
        self._parts += 1
        return frame

    def _with_header_timing(self, frame: Frame, fields: dict[str, Any]) -> Frame:
        """``frame`` re-timed by its part's X-Line-Time-Ns / X-Shutter / X-Readout headers."""
        from dataclasses import replace

        header_line = fields.get("line_time_ns")
        shutter = fields.get("shutter")
        if shutter is None:
            shutter = frame.shutter if header_line is None else "rolling" if header_line > 0 else "global"
        readout = fields.get("readout", frame.readout)
        if shutter not in SHUTTERS:  # unknown row timing (no headers, no sensor=): only the readout is news
            return replace(frame, readout=readout)
        n = frame.width if readout.by_column else frame.height
        t0 = frame.timestamp_ns + frame.exposure_ns // 2
        timing = self._rolling_timing(header_line, n) if shutter == "rolling" else None
        return replace(frame, line_time_ns=timing.line_time_ns if timing is not None else 0, shutter=shutter,
                       readout=readout, row_times_ns=line_sample_times_ns(t0, n, timing, readout))

    def _rolling_timing(self, header_line: int | None, n_lines: int) -> LineTiming:
        """Line timing of a rolling-shutter part: the sensor's exact one when the header's whole-ns line time
        is that timing rounded (or absent), else the header's line time on a 1 GHz clock (whole ns a line)."""
        sensor = self.timer.timing.timing if self.timer.timing.shutter == "rolling" else None
        if sensor is not None and header_line in (None, sensor.line_time_ns):
            return sensor
        if not header_line:
            got = "X-Line-Time-Ns: 0" if header_line == 0 else "no X-Line-Time-Ns"
            raise ProtocolError(f"source {self.uri!r}: part header X-Shutter: rolling with {got}; the server must "
                                "send the line time, or name the sensor with #sensor=NAME")
        return LineTiming(pixel_rate_hz=NS_PER_S, line_length_pck=header_line, frame_length_lines=n_lines)

    def _close(self) -> None:
        """Close the connection (which ends the reader thread of ``latest=1``)."""
        self._response.close()
        if self._latest is not None:
            self._latest.close()

    def info(self) -> dict[str, Any]:
        """URL and row timing."""
        return {"uri": self.uri, "url": self.url, **self.timer.timing.to_json(), **self._stream_info}


def _fps(a: Frame, b: Frame) -> float:
    """The frame rate two frames' device timestamps give (per sequence step), else FFmpeg's default."""
    dt = (b.timestamp_ns - a.timestamp_ns) / max(b.sequence - a.sequence, 1)
    return round(1e9 / dt, 3) if dt > 0 else UNSTATED_FPS


def open_source(uri: SourceURI) -> HttpMjpegSource:
    """Scheme entry point for ``http://`` and ``https://``."""
    return HttpMjpegSource(uri)
