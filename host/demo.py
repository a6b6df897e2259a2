"""``rollcam demo``: a few seconds of an emulated rolling-shutter street, as a video and a contact sheet.

No hardware and no arguments needed. Streams GS/RS pairs of the same instants from ``emu:`` (fast walkers, so
the rolling-shutter skew is plain to see) and writes

- ``demo_rs.mp4``: the RS stream (H.264) with every pedestrian's GS box (green) and RS box (magenta) and a caption
  (frame, stream time, line time);
- ``contact_sheet.png``: GS and RS frames of the same instants side by side, boxes drawn, with a legend.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from rollcam.common.errors import ConfigError, RollcamError
from rollcam.sim.frame import Frame
from rollcam.sim.hwconfig import load_sensor

from .capture import Progress, write_atomic
from .sources import open_camera
from .video import VideoWriter

DEFAULT_OUT = Path("rollcam_out") / "demo"
DEFAULT_SENSOR = "letsroll"
# Street seed 4 seen from camera 2 (across the pavement) keeps four to six sizeable walkers in view.
DEFAULT_SEED, DEFAULT_CAMERA = 4, 2
DEFAULT_SECONDS = 2.0
MAX_WIDTH_PX = 960  # half of 1080p: renders fast on a laptop and the skew is still obvious
SHEET_ROWS = 4
SHEET_TILE_WIDTH_PX = 480

GS_BGR = (80, 220, 80)  # green
RS_BGR = (230, 60, 230)  # magenta
TEXT_BGR = (255, 255, 255)
BAND_BGR = (30, 30, 30)
MIN_BOX_HEIGHT_PX = 6  # boxes of walkers far down the street would only clutter the picture


@dataclass
class DemoResult:
    """Where the demo wrote its files and what it saw."""

    video: Path
    contact_sheet: Path
    uri: str
    frames: int
    fps: float
    line_time_ns: int
    pedestrians: int
    mean_shift_px: float
    stats: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> str:
        """The one-line summary the CLI prints."""
        return (f"{self.frames} frames at {self.fps:.4g} fps, {self.pedestrians} pedestrians, mean |RS-GS| box "
                f"centre shift {self.mean_shift_px:.1f} px (line time {self.line_time_ns / 1000:.2f} us)")


def default_size(sensor: str) -> tuple[int, int]:
    """The sensor's default mode scaled down to at most ``MAX_WIDTH_PX`` wide, same aspect, even sides."""
    mode = load_sensor(sensor).mode()
    if mode.width <= MAX_WIDTH_PX:
        return mode.width, mode.height
    h = round(mode.height * MAX_WIDTH_PX / mode.width)
    return MAX_WIDTH_PX, h + h % 2


def demo_uri(sensor: str, size: tuple[int, int], seed: int = DEFAULT_SEED, camera: int = DEFAULT_CAMERA) -> str:
    """The ``emu:`` URI the demo streams."""
    return f"emu:{sensor}?scene=street&seed={seed}&camera={camera}&speed=fast&size={size[0]}x{size[1]}"


def _shown(frame: Frame) -> list:
    return [o for o in frame.objects or () if o.box_rs is not None
            and o.box_rs[3] - o.box_rs[1] >= MIN_BOX_HEIGHT_PX]


def draw_boxes(image: np.ndarray, frame: Frame, *, gs: bool = True, rs: bool = True, thickness: int = 1) -> None:
    """Draw the ground-truth boxes of ``frame``'s pedestrians onto ``image`` (same size as the frame)."""
    import cv2

    sy, sx = image.shape[0] / frame.height, image.shape[1] / frame.width
    for o in _shown(frame):
        for box, colour, on in ((o.box_gs, GS_BGR, gs), (o.box_rs, RS_BGR, rs)):
            if on and box is not None:
                p0 = (round(box[0] * sx), round(box[1] * sy))
                p1 = (max(round(box[2] * sx) - 1, p0[0]), max(round(box[3] * sy) - 1, p0[1]))
                cv2.rectangle(image, p0, p1, colour, thickness, cv2.LINE_AA)


def caption(image: np.ndarray, text: str, *, scale: float | None = None) -> np.ndarray:
    """``image`` with a dark band holding ``text`` on top (a new array, same width)."""
    import cv2

    scale = scale or max(image.shape[1] / 1600.0, 0.4)
    (_, th), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    band = np.full((th + base + 10, image.shape[1], 3), BAND_BGR, np.uint8)
    cv2.putText(band, text, (6, th + 5), cv2.FONT_HERSHEY_SIMPLEX, scale, TEXT_BGR, 1, cv2.LINE_AA)
    return np.vstack([band, image])


def _legend(width: int) -> np.ndarray:
    import cv2

    band = np.full((34, width, 3), BAND_BGR, np.uint8)
    x = 8
    for colour, text in ((GS_BGR, "GS box: every row at the frame's reference time"),
                         (RS_BGR, "RS box: each row at its own read-out time")):
        cv2.rectangle(band, (x, 10), (x + 22, 24), colour, 2)
        cv2.putText(band, text, (x + 30, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.45, TEXT_BGR, 1, cv2.LINE_AA)
        x += 30 + cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, 0.45, 1)[0][0] + 24
    return band


def contact_sheet(pairs: Sequence[tuple[Frame, Frame]], tile_width: int = SHEET_TILE_WIDTH_PX) -> np.ndarray:
    """A grid of (GS, RS) pairs, one instant a row, GS left and RS right, boxes drawn, legend on top."""
    import cv2

    rows = []
    for gs, rs in pairs:
        tiles = []
        for frame, name in ((gs, "GS"), (rs, "RS")):
            h = round(frame.height * tile_width / frame.width)
            img = cv2.resize(np.ascontiguousarray(frame.data), (tile_width, h), interpolation=cv2.INTER_AREA)
            draw_boxes(img, frame, gs=True, rs=name == "RS")
            t_s = frame.timestamp_ns / 1e9
            label = f"{name} frame {frame.sequence}  t={t_s:.4f} s  line time {frame.line_time_ns / 1000:.2f} us"
            tiles.append(caption(img, label, scale=0.4))
        rows.append(np.hstack([tiles[0], np.full((tiles[0].shape[0], 4, 3), 255, np.uint8), tiles[1]]))
    sep = np.full((4, rows[0].shape[1], 3), 255, np.uint8)
    body = [rows[0]]
    for r in rows[1:]:
        body += [sep, r]
    return np.vstack([_legend(rows[0].shape[1]), *body])


def _centre_shift(frame: Frame) -> list[float]:
    out = []
    for o in frame.objects or ():
        if o.box_gs is not None and o.box_rs is not None:
            g, r = o.box_gs, o.box_rs
            out.append(math.hypot((r[0] + r[2] - g[0] - g[2]) / 2, (r[1] + r[3] - g[1] - g[3]) / 2))
    return out


def run_demo(
    out_dir: str | os.PathLike[str] = DEFAULT_OUT,
    *,
    seconds: float = DEFAULT_SECONDS,
    sensor: str = DEFAULT_SENSOR,
    size: tuple[int, int] | None = None,
    seed: int = DEFAULT_SEED,
    camera: int = DEFAULT_CAMERA,
    progress: bool | None = None,
    stream: TextIO | None = None,
) -> DemoResult:
    """Stream ``seconds`` of the emulated street and write the video and contact sheet into ``out_dir``."""
    import cv2

    if not math.isfinite(seconds) or seconds <= 0:
        raise ConfigError(f"seconds must be a positive number, got {seconds!r}")
    size = size or default_size(sensor)
    uri = demo_uri(sensor, size, seed, camera)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {str(out)!r} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    video, sheet = out / "demo_rs.mp4", out / "contact_sheet.png"
    with open_camera(uri) as source:
        info = source.info()
        fps = float(info["fps"])
        n = max(1, round(seconds * fps))
        picks = set(np.linspace(0, n - 1, min(SHEET_ROWS, n)).round().astype(int).tolist())
        writer = None
        sheet_pairs: list[tuple[Frame, Frame]] = []
        shifts: list[float] = []
        seen: set[int] = set()
        bar = Progress(n, label="demo", stream=stream, enabled=progress)
        finished = False
        try:
            for i in range(n):
                pair = source.read_pair()
                if pair is None:
                    break
                rs = pair[1]
                shifts += _centre_shift(rs)
                seen.update(o.id for o in _shown(rs))
                if i in picks:
                    sheet_pairs.append(pair)
                img = np.ascontiguousarray(rs.data).copy()
                draw_boxes(img, rs, thickness=2 if img.shape[1] >= 1280 else 1)
                text = (f"RS frame {rs.sequence}  t={rs.timestamp_ns / 1e9:.3f} s  line time "
                        f"{rs.line_time_ns / 1000:.2f} us   green: GS box  magenta: RS box")
                img = caption(img, text)
                if writer is None:
                    writer = VideoWriter(video, fps, (img.shape[1], img.shape[0]))
                writer.write(img)
                bar.update(i + 1)
            finished = True
        finally:
            bar.close()
            if writer is not None and finished:
                writer.close()
            elif writer is not None:  # interrupted or failed: leave no half-written video behind
                writer.abort()
        if not sheet_pairs:
            raise RollcamError(f"source {uri!r} gave no frames")
    ok, png = cv2.imencode(".png", contact_sheet(sheet_pairs))
    if not ok:
        raise RollcamError("could not encode the contact sheet as PNG")
    write_atomic(sheet, png.tobytes())
    return DemoResult(video, sheet, uri, n, fps, int(info["line_time_ns"]), len(seen),
                      float(np.mean(shifts)) if shifts else 0.0,
                      {"max_shift_px": float(np.max(shifts)) if shifts else 0.0, "size": list(size)})
