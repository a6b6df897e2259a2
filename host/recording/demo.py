"""``rollcam demo``: a few seconds of an emulated rolling-shutter street, as a video and a contact sheet.

No hardware and no arguments needed. Streams GS/RS pairs of the same instants from ``emu:`` (fast walkers, so
the rolling-shutter skew is plain to see) and writes

- ``demo_rs.mp4``: the RS stream (H.264) with every pedestrian's GS box (green) and RS box (magenta) and a caption
  (frame, stream time, line time);
- ``contact_sheet.png``: GS and RS frames of the same instants side by side, boxes drawn, with a legend.

The demo follows the sensor's shutter: a global-shutter sensor (``--sensor ov9281``) exposes every row at
once, so it streams GS frames only, writes ``demo_gs.mp4`` with the GS boxes, a one-column contact sheet, and
reports no rolling-shutter shift.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

import numpy as np
from rollcam.common.errors import ConfigError, RollcamError
from rollcam.common.files import output_dir, write_atomic
from rollcam.common.lifecycle import Stats
from rollcam.sim.codecs import encode_image
from rollcam.sim.frame import Frame
from rollcam.sim.hwconfig import load_sensor

from ..progress import Progress
from ..sources import open_camera
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


@dataclass(frozen=True)
class DemoStats(Stats):
    """The demo's extra figures: the largest RS-GS box-centre shift, and the frame size streamed."""

    max_shift_px: float = 0.0
    size: tuple[int, int] = (0, 0)


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
    stats: DemoStats = field(default_factory=DemoStats)
    shutter: str = "rolling"

    def summary(self) -> str:
        """The one-line summary the CLI prints."""
        head = f"{self.frames} frames at {self.fps:.4g} fps, {self.pedestrians} pedestrians, "
        if self.shutter == "global":
            return head + "global shutter: every row exposed at once, so no rolling-shutter skew to show"
        return head + (f"mean |RS-GS| box centre shift {self.mean_shift_px:.1f} px (line time "
                       f"{self.line_time_ns / 1000:.2f} us)")


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


def _legend(width: int, rolling: bool = True) -> np.ndarray:
    import cv2

    band = np.full((34, width, 3), BAND_BGR, np.uint8)
    x = 8
    keys = [(GS_BGR, "GS box: every row at the frame's reference time")]
    if rolling:
        keys.append((RS_BGR, "RS box: each row at its own read-out time"))
    for colour, text in keys:
        cv2.rectangle(band, (x, 10), (x + 22, 24), colour, 2)
        cv2.putText(band, text, (x + 30, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.45, TEXT_BGR, 1, cv2.LINE_AA)
        x += 30 + cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, 0.45, 1)[0][0] + 24
    return band


def contact_sheet(pairs: Sequence[tuple[Frame, Frame | None]], tile_width: int = SHEET_TILE_WIDTH_PX) -> np.ndarray:
    """A grid of (GS, RS) pairs, one instant a row, GS left and RS right, boxes drawn, legend on top; pairs
    without an RS frame (a global-shutter sensor) make a one-column sheet of GS frames."""
    import cv2

    rolling = all(rs is not None for _, rs in pairs)
    rows = []
    for gs, rs in pairs:
        tiles = []
        for frame, name in ((gs, "GS"), (rs, "RS")) if rolling else ((gs, "GS"),):
            h = round(frame.height * tile_width / frame.width)
            img = cv2.resize(np.ascontiguousarray(frame.data), (tile_width, h), interpolation=cv2.INTER_AREA)
            draw_boxes(img, frame, gs=True, rs=name == "RS")
            t_s = frame.timestamp_ns / 1e9
            label = f"{name} frame {frame.sequence}  t={t_s:.4f} s  line time {frame.line_time_ns / 1000:.2f} us"
            tiles.append(caption(img, label, scale=0.4))
        if len(tiles) == 1:
            rows.append(tiles[0])
        else:
            rows.append(np.hstack([tiles[0], np.full((tiles[0].shape[0], 4, 3), 255, np.uint8), tiles[1]]))
    sep = np.full((4, rows[0].shape[1], 3), 255, np.uint8)
    body = [rows[0]]
    for r in rows[1:]:
        body += [sep, r]
    return np.vstack([_legend(rows[0].shape[1], rolling), *body])


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
    if not math.isfinite(seconds) or seconds <= 0:
        raise ConfigError(f"seconds must be a positive number, got {seconds!r}")
    size = size or default_size(sensor)
    uri = demo_uri(sensor, size, seed, camera)
    out = output_dir(out_dir)
    with open_camera(uri) as source:
        info = source.info()
        rolling = info.get("shutter") != "global"  # a GS sensor's frames are GS: no RS frame is claimed
        name = "demo_rs" if rolling else "demo_gs"
        video, sheet = out / f"{name}.mp4", out / "contact_sheet.png"
        fps = float(info["fps"])
        n = max(1, round(seconds * fps))
        picks = set(np.linspace(0, n - 1, min(SHEET_ROWS, n)).round().astype(int).tolist())
        writer = None
        sheet_pairs: list[tuple[Frame, Frame | None]] = []
        shifts: list[float] = []
        seen: set[int] = set()
        bar = Progress(n, label="demo", stream=stream, enabled=progress)
        finished = False
        try:
            for i in range(n):
                if rolling:
                    pair = source.read_pair()
                    shown = None if pair is None else pair[1]
                else:
                    shown = source.read()
                    pair = None if shown is None else (shown, None)
                if pair is None or shown is None:
                    break
                if rolling:
                    shifts += _centre_shift(shown)
                seen.update(o.id for o in _shown(shown))
                if i in picks:
                    sheet_pairs.append(pair)
                img = np.ascontiguousarray(shown.data).copy()
                draw_boxes(img, shown, rs=rolling, thickness=2 if img.shape[1] >= 1280 else 1)
                if rolling:
                    text = (f"RS frame {shown.sequence}  t={shown.timestamp_ns / 1e9:.3f} s  line time "
                            f"{shown.line_time_ns / 1000:.2f} us   green: GS box  magenta: RS box")
                else:
                    text = (f"GS frame {shown.sequence}  t={shown.timestamp_ns / 1e9:.3f} s  global shutter: "
                            "every row at once   green: GS box")
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
    write_atomic(sheet, encode_image(contact_sheet(sheet_pairs), "png", error=RollcamError, what="the contact sheet"))
    return DemoResult(video, sheet, uri, n, fps, int(info["line_time_ns"]), len(seen),
                      float(np.mean(shifts)) if shifts else 0.0,
                      DemoStats(float(np.max(shifts)) if shifts else 0.0, (int(size[0]), int(size[1]))),
                      "rolling" if rolling else "global")
