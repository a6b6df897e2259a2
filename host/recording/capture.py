"""``rollcam capture``: frames of any source to image files and ``frames.jsonl``, without losing any.

Each image is written durably under a temporary name and moved into place (``rollcam.common.files``); only
then is its ``frames.jsonl`` record appended, the records of a GS/RS pair in one write, and a failed append
is cut back to the last whole line. So however a capture stops (Ctrl-C, a full disk, an I/O error, ``kill
-9``, a finite source running out), ``frames.jsonl`` holds whole records of images that exist, an image
whose record did not go in is removed, and no temporary file is left behind; after a power cut or a kill
in the middle of an append, the torn last line that may remain is skipped by ``read_capture``.
``capture.json`` beside it records the source's ``info()``, the command line and, once the capture has
ended, how it ended and what it kept (``frames``, ``images``, ``complete``; ``error`` after a failure);
``read_capture`` counts from ``frames.jsonl`` itself, so the two never disagree. Nothing is written (not
even the folder) before the options are accepted and the first frames are known to fit the image format,
so a refused capture leaves nothing that would refuse the corrected command.

Images are named by instant and shutter: ``NNNNNN_rs.png`` / ``NNNNNN_gs.png``, or ``NNNNNN.png`` for a camera
whose shutter is unknown (a webcam through ``opencv:`` without ``sensor=``).

A recording format (``RECORDING_FORMATS``) puts the whole capture into one file instead, beside
``capture.json``: ROS messages in MCAP or a ROS 2 / ROS 1 / Kalibr bag, or an H.264 video with Gyroflow's
``.gcsv`` (``rollcam.host.robotics``); the recording is renamed into place when the capture ends, whole, and
Ctrl-C ends it with the instants it has.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from rollcam.common.errors import ConfigError, SourceError, is_interrupt
from rollcam.common.files import OS_FS, AppendLog, FileSystem, output_dir, part_target, read_jsonl, write_atomic
from rollcam.sim.frame import Frame

from ..progress import Progress
from ..robotics import bags, gcsv
from ..robotics.bags import BAG_FORMATS
from ..sources import CameraSource
from .imagefiles import encode_image, image_array
from .imu_export import ImuLog

FRAMES_LOG = "frames.jsonl"
CAPTURE_INFO = "capture.json"
IMAGE_FORMATS = ("png", "jpg", "npy")
RECORDING_FORMATS = (*BAG_FORMATS, "mp4")
"""Formats that record the whole capture in one file (or ROS 2 bag folder) instead of an image per frame."""
CAPTURE_FORMATS = IMAGE_FORMATS + RECORDING_FORMATS
SHUTTER_CHOICES = ("rolling", "global", "both")
SUFFIX = {"rolling": "_rs", "global": "_gs"}
"""File-name suffix of each shutter; any other (``unknown``) gets none."""
# Files a capture writes (and their temporary files); --overwrite removes only these, nothing else the folder holds.
_CAPTURE_FILE = re.compile(r"\d{6,}(_rs|_gs)?\.(png|jpg|npy)|\.?(frames\.jsonl|capture\.json|imu\.csv|camera_poses\.csv"
                           r"|imu\.yaml|camchain\.yaml|camera\.yaml|camchain-imucam\.yaml"
                           r"|capture\.mcap|capture_ros2|capture\.bag|kalibr\.bag|capture\.mp4|capture\.gcsv)")
_INSTANT = re.compile(r"\d+")


def _is_capture_file(name: str) -> bool:
    return bool(_CAPTURE_FILE.fullmatch(part_target(name) or name))


@dataclass
class CaptureResult:
    """What a capture wrote: instants captured, image files, where, how long it took, whether it finished."""

    out_dir: Path
    frames: int
    images: int
    seconds: float
    complete: bool
    recording: Path | None = None
    """The MCAP file, bag or video of a recording format (no images or ``frames.jsonl`` then)."""

    def to_json(self) -> dict[str, Any]:
        """The summary ``rollcam capture --json`` prints."""
        out = {"frames": self.frames, "images": self.images, "out": str(self.out_dir),
               "frames_jsonl": str(self.out_dir / FRAMES_LOG), "seconds": round(self.seconds, 3),
               "complete": self.complete}
        if self.recording is not None:
            del out["frames_jsonl"]
            out["recording"] = str(self.recording)
        return out


class CaptureInterrupted(KeyboardInterrupt):
    """Ctrl-C during a capture, raised after cleanup; ``result`` says what was kept."""

    def __init__(self, result: CaptureResult) -> None:
        super().__init__(f"capture interrupted after {result.frames} frame(s)")
        self.result = result


def check_out_dir(out_dir: Path, overwrite: bool) -> None:
    """Refuse an ``out_dir`` that is a file, or holds a capture while ``overwrite`` is off; writes nothing."""
    output_dir(out_dir, make=False)
    held = next((n for n in (FRAMES_LOG, CAPTURE_INFO) if (out_dir / n).exists()), None)
    if held is not None and not overwrite:
        raise ConfigError(f"{str(out_dir)!r} already holds a capture ({held}); pass --overwrite to "
                          "replace it, or choose another --out")


def prepare_out_dir(out_dir: Path, overwrite: bool) -> None:
    """Create ``out_dir``; refuse one that already holds a capture unless ``overwrite`` (then clear it)."""
    check_out_dir(out_dir, overwrite)
    output_dir(out_dir)
    if (out_dir / FRAMES_LOG).exists() or (out_dir / CAPTURE_INFO).exists():
        for p in out_dir.iterdir():
            if p.is_file() and _is_capture_file(p.name):
                p.unlink()
            elif p.is_dir() and not p.is_symlink() and _is_capture_file(p.name):  # a ROS 2 bag, a bag's stage
                shutil.rmtree(p)


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
    """Image files plus ``frames.jsonl`` records, written so that a record is whole or absent after any failure,
    and an image is there for every record (see the module docstring). ``fs`` is the file-system seam."""

    def __init__(self, out_dir: Path, fmt: str = "png", *, fs: FileSystem = OS_FS, fps: float | None = None) -> None:
        if fmt not in IMAGE_FORMATS:
            raise ConfigError(f"image format {fmt!r} is not one of {list(IMAGE_FORMATS)}")
        self.out_dir, self.fmt, self.fs, self.fps = out_dir, fmt, fs, fps
        self._imu: ImuLog | None = None  # IMU files, from the first frame that carries samples
        self.frames = self.images = 0
        self._log: AppendLog | None = AppendLog(out_dir / FRAMES_LOG, truncate=True, fs=fs)

    def write(self, frames: Sequence[Frame]) -> None:
        """Store the frames of one instant: durable images first, then their records in one append."""
        if self._log is None:
            raise ValueError("capture writer is closed")
        records: list[str] = []
        written: list[Path] = []
        start = self._log.size
        try:
            for frame in frames:
                path = self.out_dir / f"{self.frames:06d}{SUFFIX.get(frame.shutter, '')}.{self.fmt}"
                data = encode_image(frame, self.fmt)
                written.append(path)  # listed before it exists, so an interrupt mid-write still removes it
                write_atomic(path, data, self.fs)
                records.append(json.dumps(frame.to_json(path.name), default=_json_default))
            self._write_imu(frames)
            self._log.append("".join(r + "\n" for r in records).encode("utf-8"))
        except BaseException:
            # The log's committed size says whether the records went in, wherever an error or interrupt landed:
            # if they did, the images stay; if not, the images go (half a pair is no record). An unknown tail
            # (the cut-back itself failed) keeps the images: never a record without its image.
            if self._log.size == start:
                for path in written:
                    with contextlib.suppress(OSError):
                        self.fs.unlink(path)
            elif self._log.size is not None:
                self.frames += 1
                self.images += len(records)
            raise
        self.frames += 1
        self.images += len(records)

    def _write_imu(self, frames: Sequence[Frame]) -> None:
        """The instant's IMU and per-line pose rows (before its records: a sample row may outlive a failed
        record, never a record its samples)."""
        with_imu = [f for f in frames if f.imu is not None]
        if not with_imu:
            return
        first = next((f for f in with_imu if f.shutter == "rolling"), with_imu[0])  # its line delay
        if self._imu is None:
            self._imu = ImuLog(self.out_dir, first, {"fps": self.fps}, fs=self.fs)
        self._imu.write(frames)

    def close(self) -> None:
        """fsync the logs and close them; safe to call twice."""
        if self._imu is not None:
            imu, self._imu = self._imu, None
            imu.close()
        if self._log is not None:
            log, self._log = self._log, None
            log.close()


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


def write_capture_info(out_dir: Path, info: dict[str, Any], fs: FileSystem = OS_FS) -> None:
    """Store ``capture.json`` atomically."""
    text = json.dumps(info, indent=2, default=_json_default) + "\n"
    write_atomic(out_dir / CAPTURE_INFO, text.encode("utf-8"), fs)


def read_capture(out_dir: str | os.PathLike[str]) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """A capture folder's ``capture.json`` and its ``frames.jsonl`` records (a torn last line left out).

    ``frames`` and ``images`` in the returned info are counted from the records, which are the truth: a
    capture stopped before it could rewrite ``capture.json`` (a full disk, a kill) still reads right.
    """
    out = Path(out_dir)
    info = json.loads((out / CAPTURE_INFO).read_text(encoding="utf-8"))
    records = read_jsonl(out / FRAMES_LOG)
    instants = {m.group() for r in records if (m := _INSTANT.match(str(r.get("file", ""))))}
    info.update(frames=len(instants), images=len(records))
    return info, records


def _writer(out: Path, fmt: str, fs: FileSystem, info: dict[str, Any], storage: str) -> CaptureWriter | \
        bags.BagWriter | gcsv.VideoWithGyro:
    """The writer of ``fmt``: image files and ``frames.jsonl``, a bag or MCAP file, or a video and its gcsv."""
    fps = info["source"].get("fps")
    if fmt in BAG_FORMATS:
        info["recording"] = bags.OUTPUT[fmt]
        return bags.BagWriter(out, fmt, storage=storage)
    if fmt == "mp4":
        info["recording"] = gcsv.VIDEO_NAME
        started = datetime.fromisoformat(info["started_utc"])
        return gcsv.VideoWithGyro(out, fps, timestamp_s=int(started.timestamp()))
    return CaptureWriter(out, fmt, fs=fs, fps=fps)


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
    fs: FileSystem = OS_FS,
    bag_storage: str = "sqlite3",
) -> CaptureResult:
    """Capture ``frames`` instants of ``source`` into ``out_dir`` (see the module docstring).

    ``progress`` None shows progress on ``stream`` (stderr) only when it is a terminal. Ends early, and
    reports it, when a finite source runs out. Ctrl-C raises ``CaptureInterrupted`` after cleanup; a write
    error (a full disk) propagates after it, with every record already written kept whole. ``fs``: the
    file-system seam (tests make its calls fail). ``fmt`` is an image format (``IMAGE_FORMATS``) or a recording
    (``RECORDING_FORMATS``: ``rollcam.host.robotics``); ``bag_storage`` a ROS 2 bag's storage (sqlite3, mcap).
    """
    if isinstance(frames, bool) or not isinstance(frames, int) or frames <= 0:
        raise ConfigError(f"frames must be a positive integer, got {frames!r}")
    if fmt not in CAPTURE_FORMATS:
        raise ConfigError(f"capture format {fmt!r} is not one of {list(CAPTURE_FORMATS)}")
    out = Path(out_dir)
    read = frame_reader(source, shutter)
    check_out_dir(out, overwrite)
    if bag_storage not in bags.ROS2_STORAGES:
        raise ConfigError(f"ROS 2 bag storage {bag_storage!r} is not one of {list(bags.ROS2_STORAGES)}")
    if fmt in BAG_FORMATS:
        bags.require_libraries(fmt)  # a missing extra is named before any frame is made
    # The first instant is read before anything is written, and checked against the format: a frame the
    # format cannot hold (jpg of a raw stream) is refused while the folder is still as it was.
    first = read()
    if first and fmt in BAG_FORMATS:
        bags.check_frames(first, fmt)
    elif first and fmt == "mp4":
        gcsv.check_frames(first)
    for frame in first or ():
        if fmt in ("png", "jpg"):
            image_array(frame, fmt)
    prepare_out_dir(out, overwrite)
    info: dict[str, Any] = {
        "command": list(command) if command is not None else None,
        "source": source.info(),
        "shutter": shutter or "source",
        "image_format": fmt,
        "frames_requested": frames,
        "started_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "complete": False,  # frames/images/complete are added when the capture ends (read_capture counts them)
    }
    write_capture_info(out, info, fs)
    if fmt == "ros2bag":
        info["bag_storage"] = bag_storage
    writer = _writer(out, fmt, fs, info, bag_storage)
    bar = Progress(frames, label="capture", stream=stream, enabled=progress, unit="frame")
    start = clock()
    interrupted = False
    error: BaseException | None = None
    try:
        pending = first
        while pending is not None:
            writer.write(pending)
            bar.update(writer.frames)
            pending = read() if writer.frames < frames else None
    except KeyboardInterrupt:
        interrupted = True
    except BaseException as exc:
        if not is_interrupt(exc):
            error = exc
            raise
        interrupted = True  # Ctrl-C inside compiled code (see ``is_interrupt``)
    finally:
        bar.close()
        try:
            writer.close()
            recording = out / info["recording"] if "recording" in info else None
            result = CaptureResult(out, writer.frames, writer.images, clock() - start, writer.frames == frames,
                                   recording if recording is not None and recording.exists() else None)
            info.update(frames=result.frames, images=result.images, seconds=round(result.seconds, 3),
                        complete=result.complete, interrupted=interrupted)
            if error is not None:
                info["error"] = f"{type(error).__name__}: {error}"
            write_capture_info(out, info, fs)
        except OSError:
            # After a failure (a full disk) the first error is the one to report; capture.json then still
            # says the capture never finished, and read_capture counts frames.jsonl.
            if error is None:
                raise
    if interrupted:
        raise CaptureInterrupted(result)
    return result
