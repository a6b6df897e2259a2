"""What a render of the per-line renderer returns: images, linear radiance, and exact per-line ground truth.

``RenderResult`` is a frame (8-bit BGR, optionally linear RGB) with its ``LineTruth``, filled by the line
kernel as it paints (each actor's extent along each line, its covered and visible pixels). ``LinearFrame`` is
the sensor path's radiance: the renderer's shared static composite plus the lines painted over it.
``object_truths`` turns a frame's line truth and the truth at its reference instant into the ``ObjectTruth``
records a ``Frame`` carries.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..frame import Box, ObjectTruth


@dataclass
class LineTruth:
    """Per-actor, per-line ground truth of one render, in render space (lines x along-line position)."""

    left: np.ndarray  # (actors, lines) float64, NaN where the actor has no pixel on the line
    right: np.ndarray
    area: np.ndarray  # (actors, lines) int64: pixels whose centre the actor covers
    visible: np.ndarray  # (actors, lines) int64: of those, pixels no nearer actor hides
    transposed: bool

    @classmethod
    def empty(cls, n_actors: int, n_lines: int, transposed: bool) -> LineTruth:
        """Arrays for a render of ``n_lines`` lines."""
        return cls(
            np.full((n_actors, n_lines), np.nan),
            np.full((n_actors, n_lines), np.nan),
            np.zeros((n_actors, n_lines), np.int64),
            np.zeros((n_actors, n_lines), np.int64),
            transposed,
        )

    def boxes(self) -> list[Box | None]:
        """Image-space box of each actor: union of its per-line extents (None when it has no pixel)."""
        has = ~np.isnan(self.left)
        n_lines = has.shape[1]
        if n_lines == 0:
            return [None] * has.shape[0]
        any_line = has.any(axis=1)
        first = np.argmax(has, axis=1)
        last = n_lines - 1 - np.argmax(has[:, ::-1], axis=1)
        a0s = np.where(has, self.left, np.inf).min(axis=1)
        a1s = np.where(has, self.right, -np.inf).max(axis=1)
        out: list[Box | None] = []
        for o in range(has.shape[0]):
            if not any_line[o]:
                out.append(None)
                continue
            a0, a1 = float(a0s[o]), float(a1s[o])
            b0, b1 = float(first[o]), float(last[o] + 1)
            out.append((b0, a0, b1, a1) if self.transposed else (a0, b0, a1, b1))
        return out

    def visible_fraction(self) -> np.ndarray:
        """Fraction of each actor's in-image pixels not hidden by nearer actors (0 when none)."""
        tot = self.area.sum(axis=1)
        vis = self.visible.sum(axis=1)
        return np.where(tot > 0, vis / np.maximum(tot, 1), 0.0)


@dataclass
class RenderResult:
    """A rendered image (8-bit BGR, optionally linear RGB float32) and its per-line ground truth."""

    image: np.ndarray
    linear: np.ndarray | None
    truth: LineTruth
    lines_painted: int = 0  # lines rendered rather than copied from the static cache
    radiance: LinearFrame | None = None  # render_linear's result (image and linear are then empty/None)


@dataclass
class LinearFrame:
    """Linear RGB radiance of a frame, held as the renderer's static composite plus the lines painted over it.

    ``static`` and ``lines`` are float32 ``(lines, pixels per line, 3)`` in render orientation (rows, or
    columns when ``by_column``); line i of the frame is ``lines[i]`` where ``painted[i]``, else ``static[i]``.
    ``static`` is the renderer's cache, shared and never written (None for a moving camera, when every line is
    painted). This lets the sensor path read untouched lines in place instead of copying 25 MB per frame.
    """

    static: np.ndarray | None
    lines: np.ndarray
    painted: np.ndarray  # (lines,) bool
    by_column: bool = False

    def full(self) -> np.ndarray:
        """The whole frame as one fresh float32 ``(H, W, 3)`` array in image orientation."""
        if self.static is None:
            out = self.lines.copy()
        else:
            out = self.static.copy()
            idx = np.flatnonzero(self.painted)
            out[idx] = self.lines[idx]
        return out.transpose(1, 0, 2) if self.by_column else out


def object_truths(frame_truth: LineTruth, gs_truth: LineTruth, ids: Sequence[int], classes: Sequence[str],
                  speeds_mps: Sequence[float], labelled: Sequence[bool] | None = None) -> tuple[ObjectTruth, ...]:
    """Per-object truth of a frame: RS boxes from ``frame_truth``, GS boxes from ``gs_truth`` (every line at the
    reference instant), visibility in the frame's own shutter. Objects with no pixel under either are left out,
    and so are actors not ``labelled`` (scenery such as street props; default: every actor is labelled)."""
    rs_boxes = frame_truth.boxes()
    gs_boxes = gs_truth.boxes()
    vis = frame_truth.visible_fraction()
    out = []
    for o in range(len(ids)):
        if (rs_boxes[o] is None and gs_boxes[o] is None) or (labelled is not None and not labelled[o]):
            continue
        out.append(ObjectTruth(ids[o], classes[o], gs_boxes[o], rs_boxes[o], float(vis[o]), float(speeds_mps[o])))
    return tuple(out)
