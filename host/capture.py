"""``rollcam capture``: frames of any source to image files and ``frames.jsonl``, without losing any.

Each image is written under a temporary name and moved into place with ``os.replace``; its ``frames.jsonl``
record is appended (and flushed) only once the image is there, and the two frames of a GS/RS pair go in as
one write. However a capture stops (Ctrl-C, an error, a finite source running out), ``frames.jsonl`` holds
complete records of images that exist, and no temporary file is left behind. ``capture.json`` beside it
records the source's ``info()``, the command line and whether the capture completed. Nothing is written
(not even the folder) before the options are accepted and the first frames are known to fit the image format,
so a refused capture leaves nothing that would refuse the corrected command.

Images are named by instant and shutter: ``NNNNNN_rs.png`` / ``NNNNNN_gs.png``, or ``NNNNNN.png`` for a camera
whose shutter is unknown (a webcam through ``opencv:`` without ``sensor=``).
"""

from __future__ import annotations

import json
import os
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from rollcam.common.errors import ConfigError, SourceError
from rollcam.sim.codecs import codec
from rollcam.sim.formats import FORMATS
from rollcam.sim.frame import Frame

from .progress import Progress
from .sources import CameraSource

FRAMES_LOG = "frames.jsonl"
CAPTURE_INFO = "capture.json"
IMAGE_FORMATS = ("png", "jpg", "npy")
SHUTTER_CHOICES = ("rolling", "global", "both")
SUFFIX = {"rolling": "_rs", "global": "_gs"}
"""File-name suffix of each shutter; any other (``unknown``) gets none."""
_TMP_SUFFIX = ".part"
# Files a capture writes; --overwrite removes only these, never anything else the folder holds.
_CAPTURE_FILE = re.compile(r"\d{6,}(_rs|_gs)?\.(png|jpg|npy)(\.part)?|\.?(frames\.jsonl|capture\.json)(\.part)?")


@dataclass
class CaptureResult:
    """What a capture wrote: instants captured, image files, where, how long it took, whether it finished."""

    out_dir: Path
    frames: int
    images: int
    seconds: float
    complete: bool

    def to_json(self) -> dict[str, Any]:
        """The summary ``rollcam capture --json`` prints."""
        return {"frames": self.frames, "images": self.images, "out": str(self.out_dir),
                "frames_jsonl": str(self.out_dir / FRAMES_LOG), "seconds": round(self.seconds, 3),
                "complete": self.complete}


class CaptureInterrupted(KeyboardInterrupt):
    """Ctrl-C during a capture, raised after cleanup; ``result`` says what was kept."""

    def __init__(self, result: CaptureResult) -> None:
        super().__init__(f"capture interrupted after {result.frames} frame(s)")
        self.result = result


def write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` via a temporary name and ``os.replace``; never leaves a partial file."""
    tmp = path.with_name(path.name + _TMP_SUFFIX)
    try:
        with open(tmp, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


_PICTURES = ("BGR3", "RGB3", "GREY")


def image_array(frame: Frame, fmt: str) -> np.ndarray:
    """Pixel data in the layout ``cv2.imencode`` stores for image format ``fmt``.

    BGR3/RGB3 become BGR pictures, GREY a grey one. Any other format (raw Bayer or mono, CSI-2 packed,
    YUYV, NV12) is stored losslessly as its memory layout in 2-D: rows by bytes (uint8) or by samples
    (uint16, 16-bit PNG), so ``frames.jsonl``'s format, width, height and bytesperline restore the frame.
    JPEG would lose samples, so it takes only the picture formats.
    """
    data = frame.data
    if frame.format in _PICTURES or frame.format not in FORMATS:
        if data.ndim == 3 and data.shape[2] == 3:
            img = codec("RGB3").decode(data, frame.width, frame.height) if frame.format == "RGB3" else data
        elif data.ndim == 2 or (data.ndim == 3 and data.shape[2] == 1):
            img = data
        else:
            raise SourceError(f"frame {frame.sequence} ({frame.format}, shape {data.shape}) cannot be stored as an "
                              "image file; capture needs BGR3, RGB3 or single-channel frames")
        if img.dtype != np.uint8 and not (img.dtype == np.uint16 and fmt == "png"):
            raise ConfigError(f"--format {fmt} cannot hold {frame.format} frames of dtype {img.dtype}"
                              + ("; use --format png" if img.dtype == np.uint16 else ""))
        return img
    if fmt == "jpg":
        raise ConfigError(f"--format jpg would lose the samples of {frame.format!r} frames; use png or npy")
    if data.dtype not in (np.uint8, np.uint16):
        raise SourceError(f"frame {frame.sequence} ({frame.format}) has dtype {data.dtype}, not uint8/uint16")
    return data.reshape(data.shape[0], -1)


def encode_image(frame: Frame, fmt: str) -> bytes:
    """The frame as PNG or JPEG bytes, or its data array exactly as ``.npy``."""
    if fmt == "npy":
        import io

        buf = io.BytesIO()
        np.save(buf, np.ascontiguousarray(frame.data), allow_pickle=False)
        return buf.getvalue()
    import cv2

    ok, buf = cv2.imencode(f".{fmt}", image_array(frame, fmt))
    if not ok:
        raise SourceError(f"could not encode frame {frame.sequence} as {fmt}")
    return buf.tobytes()


def check_out_dir(out_dir: Path, overwrite: bool) -> None:
    """Refuse an ``out_dir`` that is a file, or holds a capture while ``overwrite`` is off; writes nothing."""
    if out_dir.exists() and not out_dir.is_dir():
        raise ConfigError(f"--out {str(out_dir)!r} exists and is not a directory")
    if (out_dir / FRAMES_LOG).exists() and not overwrite:
        raise ConfigError(f"{str(out_dir)!r} already holds a capture ({FRAMES_LOG}); pass --overwrite to "
                          "replace it, or choose another --out")


def prepare_out_dir(out_dir: Path, overwrite: bool) -> None:
    """Create ``out_dir``; refuse one that already holds a capture unless ``overwrite`` (then clear it)."""
    check_out_dir(out_dir, overwrite)
    out_dir.mkdir(parents=True, exist_ok=True)
    if (out_dir / FRAMES_LOG).exists():
        for p in out_dir.iterdir():
            if p.is_file() and _CAPTURE_FILE.fullmatch(p.name):
                p.unlink()


def frame_reader(source: CameraSource, shutter: str | None) -> Callable[[], Sequence[Frame] | None]:
    """A callable giving the frames of one instant (one frame, or a GS/RS pair) under ``shutter``.

    ``None`` keeps the source's own shutter; ``'both'`` needs a source with paired frames; ``'rolling'`` or
    ``'global'`` reads plainly when the source delivers that shutter and picks from a pair when it can.
    """
    if shutter is not None and shutter not in SHUTTER_CHOICES:
        raise ConfigError(f"shutter {shutter!r} is not one of {list(SHUTTER_CHOICES)}")

    def plain() -> Sequence[Frame] | None:
        frame = source.read()
        if frame is None:
            return None
        if shutter is not None and frame.shutter != shutter:
            raise SourceError(f"source {source.uri!r} delivers {frame.shutter}-shutter frames and cannot give "
                              f"{shutter}-shutter ones")
        return (frame,)

    if shutter is None:
        return plain
    if shutter == "both":
        if not source.supports_pairs:
            raise SourceError(f"source {source.uri!r} cannot deliver paired global/rolling frames; --shutter "
                              "both needs a source that renders or composes both (emu:, file: with a line time)")
        return source.read_pair
    if source.info().get("shutter") == shutter or not source.supports_pairs:
        return plain

    def other_shutter() -> Sequence[Frame] | None:
        frame = source.read_as(shutter)
        return None if frame is None else (frame,)

    return other_shutter


class CaptureWriter:
    """Image files plus ``frames.jsonl`` records, written so that an interruption loses nothing recorded."""

    def __init__(self, out_dir: Path, fmt: str = "png") -> None:
        if fmt not in IMAGE_FORMATS:
            raise ConfigError(f"image format {fmt!r} is not one of {list(IMAGE_FORMATS)}")
        self.out_dir, self.fmt = out_dir, fmt
        self.frames = self.images = 0
        self._log: TextIO | None = open(out_dir / FRAMES_LOG, "w", encoding="utf-8")  # noqa: SIM115

    def write(self, frames: Sequence[Frame]) -> None:
        """Store the frames of one instant: images first, then their records as one flushed write."""
        assert self._log is not None, "writer is closed"
        records: list[str] = []
        written: list[Path] = []
        start = self._log.tell()
        try:
            for frame in frames:
                path = self.out_dir / f"{self.frames:06d}{SUFFIX.get(frame.shutter, '')}.{self.fmt}"
                written.append(path)  # listed before it exists, so an interrupt mid-write still removes it
                write_atomic(path, encode_image(frame, self.fmt))
                records.append(json.dumps(frame.to_json(path.name), default=_json_default))
            self._log.write("".join(r + "\n" for r in records))
        except BaseException:
            # An interrupt can land anywhere, even just after the records went into the log's buffer: then the
            # images stay (close() flushes their records); otherwise half a pair is no record, so the folder
            # is left exactly as the log says.
            if self._log.tell() == start:
                for path in written:
                    path.unlink(missing_ok=True)
            else:
                self.frames += 1
                self.images += len(records)
            raise
        self._log.flush()
        self.frames += 1
        self.images += len(records)

    def close(self) -> None:
        """Flush the log to disk and close it; safe to call twice."""
        if self._log is not None:
            log, self._log = self._log, None
            try:
                log.flush()
                os.fsync(log.fileno())
            finally:
                log.close()


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


def write_capture_info(out_dir: Path, info: dict[str, Any]) -> None:
    """Store ``capture.json`` atomically."""
    text = json.dumps(info, indent=2, default=_json_default) + "\n"
    write_atomic(out_dir / CAPTURE_INFO, text.encode("utf-8"))


def capture(
    source: CameraSource,
    out_dir: str | os.PathLike[str],
    frames: int,
    *,
    shutter: str | None = None,
    fmt: str = "png",
    overwrite: bool = False,
    progress: bool | None = None,
    command: Sequence[str] | None = None,
    stream: TextIO | None = None,
    clock: Callable[[], float] = time.monotonic,
) -> CaptureResult:
    """Capture ``frames`` instants of ``source`` into ``out_dir`` (see the module docstring).

    ``progress`` None shows progress on ``stream`` (stderr) only when it is a terminal. Ends early, and
    reports it, when a finite source runs out. Ctrl-C raises ``CaptureInterrupted`` after cleanup.
    """
    if isinstance(frames, bool) or not isinstance(frames, int) or frames <= 0:
        raise ConfigError(f"frames must be a positive integer, got {frames!r}")
    if fmt not in IMAGE_FORMATS:
        raise ConfigError(f"image format {fmt!r} is not one of {list(IMAGE_FORMATS)}")
    out = Path(out_dir)
    read = frame_reader(source, shutter)
    check_out_dir(out, overwrite)
    # The first instant is read before anything is written, and checked against the image format: a frame the
    # format cannot hold (jpg of a raw stream) is refused while the folder is still as it was.
    first = read()
    for frame in first or ():
        if fmt != "npy":
            image_array(frame, fmt)
    prepare_out_dir(out, overwrite)
    info: dict[str, Any] = {
        "command": list(command) if command is not None else None,
        "source": source.info(),
        "shutter": shutter or "source",
        "image_format": fmt,
        "frames_requested": frames,
        "started_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "frames": 0,
        "images": 0,
        "complete": False,
    }
    write_capture_info(out, info)
    writer = CaptureWriter(out, fmt)
    bar = Progress(frames, label="capture", stream=stream, enabled=progress, unit="frame")
    start = clock()
    interrupted = False
    try:
        pending = first
        while pending is not None:
            writer.write(pending)
            bar.update(writer.frames)
            pending = read() if writer.frames < frames else None
    except KeyboardInterrupt:
        interrupted = True
    finally:
        bar.close()
        writer.close()
        result = CaptureResult(out, writer.frames, writer.images, clock() - start, writer.frames == frames)
        info.update(frames=result.frames, images=result.images, seconds=round(result.seconds, 3),
                    complete=result.complete, interrupted=interrupted)
        write_capture_info(out, info)
    if interrupted:
        raise CaptureInterrupted(result)
    return result
