"""Rolling-shutter frames composed from high-frame-rate global-shutter footage.

The original study built each 1920x1080 RS frame from 1,080 GS renders at 32,400 fps: row ``r`` of the RS
frame is row ``r`` of GS render ``r``. Here that works on any GS footage with a line time: each image line
(row, or column for column readout) is taken at its own sample time from the footage. When the footage is
slower than the line rate, lines fall between frames and are synthesised: ``nearest`` takes the nearest
frame's line, ``linear`` blends the two neighbours by time, ``flow`` warps both neighbours toward the line's
instant along DIS optical flow. A line whose time is a frame's time (within ``snap_ns``) is that frame's
line, bit for bit, under every method, so at the study's setting all three reproduce the study exactly.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Iterator
from fractions import Fraction
from typing import NamedTuple

import cv2
import numpy as np
from rollcam.common.errors import ConfigError, SourceError

from .codecs import grey_u8
from .footage import Footage, FpsLike, as_fps
from .timing import NS_PER_S, LineTiming, Readout, line_sample_times_ns

METHODS = ("nearest", "linear", "flow")
_DIS_PRESETS = {
    "ultrafast": cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST,
    "fast": cv2.DISOPTICAL_FLOW_PRESET_FAST,
    "medium": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM,
}
# A pair's flow is reused by every line between its frames; consecutive RS frames share at most the
# boundary pair, so two entries suffice (each holds the two flows, 16 bytes a pixel).
_PAIR_CACHE_SIZE = 2
# OpenCV 4.x's DIS crashes the process (segfault) on images under ~32 px in a dimension; flow is computed
# on at least this many lines (a wider band, or edge-replicated padding of a small frame).
_MIN_FLOW_PX = 64


class ComposedFrame(NamedTuple):
    """One composed RS frame of a stream: its index, first-line start, every line's sample time, pixels."""

    index: int
    t_start_ns: int
    line_times_ns: np.ndarray
    data: np.ndarray


def _cast(values: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """Float pixel values back to the footage dtype, rounding and saturating integer types."""
    if np.issubdtype(dtype, np.integer):
        info = np.iinfo(dtype)
        return np.clip(np.rint(values), info.min, info.max).astype(dtype)
    return values.astype(dtype)


def _work_dtype(dtype: np.dtype) -> type:
    # float32 holds every 8- and 16-bit value exactly; wider types blend in float64.
    return np.float32 if dtype.itemsize <= 2 and dtype.kind in "uib" else np.float64


def _dis_flow(dis: cv2.DISOpticalFlow, ga: np.ndarray, gb: np.ndarray) -> np.ndarray:
    """DIS flow from ``ga`` to ``gb``, padding images too small for DIS and cropping the flow back."""
    h, w = ga.shape
    pad_y, pad_x = max(_MIN_FLOW_PX - h, 0), max(_MIN_FLOW_PX - w, 0)
    if pad_y or pad_x:
        ga, gb = (cv2.copyMakeBorder(g, 0, pad_y, 0, pad_x, cv2.BORDER_REPLICATE) for g in (ga, gb))
    return dis.calc(ga, gb, None)[:h, :w]


def _gray_u8(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """8-bit grayscale of a frame pair for DIS (one common scale, so brightness constancy holds)."""
    if a.dtype == np.uint8 and (a.ndim == 2 or a.shape[2] in (3, 4)):
        return grey_u8(a, "rgb"), grey_u8(b, "rgb")
    ga = a.astype(np.float32) if a.ndim == 2 else a[..., :3].astype(np.float32).mean(axis=2)
    gb = b.astype(np.float32) if b.ndim == 2 else b[..., :3].astype(np.float32).mean(axis=2)
    lo = min(float(ga.min()), float(gb.min()))
    scale = 255.0 / max(max(float(ga.max()), float(gb.max())) - lo, 1e-12)
    return (
        np.clip((ga - lo) * scale + 0.5, 0, 255).astype(np.uint8),
        np.clip((gb - lo) * scale + 0.5, 0, 255).astype(np.uint8),
    )


class LineSources(NamedTuple):
    """Where each composed line comes from: the footage frames bracketing its time and the rule's choice.

    ``a``/``b`` are the frames at or before / after the line's time (equal on the last frame), ``w`` its
    fraction of the way from ``a`` to ``b``; ``nearest`` is the frame ``nearest`` composition copies (ties go to
    ``a``); ``exact`` marks lines within ``snap_ns`` of a frame's time, which every method copies from
    ``exact_k``. Image composition and label composition (``rollcam.sim.footage_labels``) both read this, so a
    label line always comes from the frame(s) its image line came from.
    """

    a: np.ndarray
    b: np.ndarray
    w: np.ndarray
    nearest: np.ndarray
    exact: np.ndarray
    exact_k: np.ndarray


def line_sources(footage: Footage, line_times_ns: np.ndarray, snap_ns: int = 1) -> LineSources:
    """The footage frames each line (absolute int64 ns time) is composed from; times off the span raise."""
    t = np.asarray(line_times_ns, dtype=np.int64)
    t0, t1 = footage.span_ns
    outside = (t < t0 - snap_ns) | (t > t1 + snap_ns)
    if np.any(outside):
        raise SourceError(
            f"line times {t[outside][:5].tolist()!r} ns (of {int(outside.sum())}) lie outside the "
            f"footage's span [{t0}, {t1}] ns "
            f"({len(footage)} frames at {float(footage.fps):g} fps)"
        )
    a = footage.index_at_or_before_ns(np.clip(t, t0, t1))
    b = np.minimum(a + 1, len(footage) - 1)
    ta, tb = footage.times_ns(a), footage.times_ns(b)
    da, db = t - ta, tb - t  # da >= -snap; db <= 0 only on the last frame
    snap_a = np.abs(da) <= snap_ns
    snap_b = ~snap_a & ((np.abs(db) <= snap_ns) | (b == a))
    span = np.maximum(tb - ta, 1)
    w = np.where(b == a, 0.0, da / span).astype(np.float64)
    return LineSources(a, b, w, np.where(da <= db, a, b), snap_a | snap_b, np.where(snap_a, a, b))


class Composer:
    """Composes RS frames from one footage with one method, keeping optical flow between calls.

    Line times are absolute footage times in int64 ns, one per image row (``by_column=False``) or column.
    ``flow_margin_px`` (flow only) computes each pair's flow on the band of lines it serves plus this margin
    instead of on the whole frame: much faster when few lines share a pair, valid while motion between the
    two frames stays well inside the margin. ``snap_ns`` absorbs the ns rounding of both clocks.
    """

    def __init__(
        self,
        footage: Footage,
        method: str = "nearest",
        *,
        by_column: bool = False,
        flow_preset: str = "medium",
        flow_margin_px: int | None = None,
        snap_ns: int = 1,
    ) -> None:
        if method not in METHODS:
            raise ConfigError(f"compose method {method!r} is not one of {METHODS}")
        if flow_preset not in _DIS_PRESETS:
            raise ConfigError(f"flow_preset {flow_preset!r} is not one of {tuple(_DIS_PRESETS)}")
        if flow_margin_px is not None and flow_margin_px < 0:
            raise ConfigError(f"flow_margin_px must be >= 0 or None, got {flow_margin_px!r}")
        self.footage = footage
        self.method = method
        self.by_column = bool(by_column)
        self.snap_ns = int(snap_ns)
        self.flow_margin_px = flow_margin_px
        self._flow_preset = flow_preset
        self._dis: cv2.DISOpticalFlow | None = None
        self._pairs: OrderedDict[tuple[int, int, int], tuple[np.ndarray, np.ndarray]] = OrderedDict()
        self.n_lines = footage.width if self.by_column else footage.height

    def _lines(self, k: int) -> np.ndarray:
        """Footage frame ``k`` with image lines along axis 0 (a transposed view for column readout)."""
        frame = self.footage[k]
        return frame.swapaxes(0, 1) if self.by_column else frame

    def compose(self, line_times_ns: np.ndarray) -> np.ndarray:
        """The RS frame whose line ``i`` is the footage at ``line_times_ns[i]`` (absolute ns)."""
        t = np.asarray(line_times_ns)
        if t.shape != (self.n_lines,) or not np.issubdtype(t.dtype, np.integer):
            raise ConfigError(
                f"line_times_ns must be {self.n_lines} integer ns times (one per "
                f"{'column' if self.by_column else 'row'}), got {t.dtype} array of shape {t.shape!r}"
            )
        src = line_sources(self.footage, t.astype(np.int64), self.snap_ns)
        lines_shape = (self.n_lines, *self._lines(0).shape[1:])
        out = np.empty(lines_shape, dtype=self.footage.dtype)

        if self.method == "nearest":
            self._gather(out, src.nearest, np.ones(self.n_lines, dtype=bool))
        else:
            # Exact frames first: a line at a frame's time is that frame's line under every method.
            self._gather(out, src.exact_k, src.exact)
            todo = np.flatnonzero(~src.exact)
            if todo.size:
                blend = self._blend_linear if self.method == "linear" else self._blend_flow
                for pair_a, sel in _groups(src.a[todo]):
                    blend(out, int(pair_a), todo[sel], src.w[todo][sel])
        return out.swapaxes(0, 1).copy() if self.by_column else out

    def _gather(self, out: np.ndarray, k: np.ndarray, use: np.ndarray) -> None:
        """Copy line ``i`` of frame ``k[i]`` for every used line: one fancy-index gather per frame."""
        rows = np.flatnonzero(use)
        for kk, sel in _groups(k[rows]):
            idx = rows[sel]
            out[idx] = self._lines(int(kk))[idx]

    def _blend_linear(self, out: np.ndarray, a: int, rows: np.ndarray, w: np.ndarray) -> None:
        wt = w.reshape(-1, *([1] * (out.ndim - 1))).astype(_work_dtype(out.dtype))
        la, lb = self._lines(a)[rows], self._lines(a + 1)[rows]
        out[rows] = _cast(la * (1 - wt) + lb * wt, out.dtype)

    def _blend_flow(self, out: np.ndarray, a: int, rows: np.ndarray, w: np.ndarray) -> None:
        """Lines at fractions ``w`` between frames ``a`` and ``a+1``, warped from both along optical flow.

        The flows from the intermediate instant back to each frame use Super SloMo's linear-motion blend
        of the two bidirectional flows (Jiang et al., CVPR 2018, eq. 4): near frame a the a->b flow, which
        is anchored where the content sits at time t, dominates, and near frame b the b->a flow does.
        """
        flow_ab, flow_ba, r0 = self._pair(a, rows)
        f_ab, f_ba = flow_ab[rows - r0], flow_ba[rows - r0]
        ww = w.astype(np.float32)[:, None, None]
        f_ta = -(1 - ww) * ww * f_ab + ww * ww * f_ba
        f_tb = (1 - ww) * (1 - ww) * f_ab - ww * (1 - ww) * f_ba
        xs = np.arange(out.shape[1], dtype=np.float32)[None, :]
        ys = rows.astype(np.float32)[:, None]

        def warp(k: int, f: np.ndarray) -> np.ndarray:
            # Bilinear backward warp of just these lines (len(rows) x width), reading only the band of
            # source lines the samples fall in, converted to float so the blend is not rounded twice.
            map_y = ys + f[..., 1]
            y0 = min(max(int(np.floor(map_y.min())), 0), self.n_lines - 1)
            y1 = min(max(int(np.floor(map_y.max())) + 2, y0 + 1), self.n_lines)
            src = np.ascontiguousarray(self._lines(k)[y0:y1], dtype=np.float32)
            res = cv2.remap(
                src, xs + f[..., 0], map_y - y0, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
            )
            return res if res.ndim == out.ndim else res[..., None]

        wt = w.reshape(-1, *([1] * (out.ndim - 1))).astype(np.float32)
        out[rows] = _cast(warp(a, f_ta) * (1 - wt) + warp(a + 1, f_tb) * wt, out.dtype)

    def _pair(self, a: int, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """Flows a->b and b->a (over all lines, or over the band of ``rows`` plus margin), cached per pair."""
        if self.flow_margin_px is None:
            r0, r1 = 0, self.n_lines
        else:
            extra = max(_MIN_FLOW_PX - (int(rows.max()) + 1 - int(rows.min())) - 2 * self.flow_margin_px, 0)
            margin = self.flow_margin_px + (extra + 1) // 2
            r0 = max(int(rows.min()) - margin, 0)
            r1 = min(int(rows.max()) + 1 + margin, self.n_lines)
        key = (a, r0, r1)
        hit = self._pairs.get(key)
        if hit is not None:
            self._pairs.move_to_end(key)
            return (*hit, r0)
        la, lb = self._lines(a), self._lines(a + 1)
        ga, gb = _gray_u8(np.ascontiguousarray(la[r0:r1]), np.ascontiguousarray(lb[r0:r1]))
        if self._dis is None:
            self._dis = cv2.DISOpticalFlow_create(_DIS_PRESETS[self._flow_preset])
        flow_ab, flow_ba = _dis_flow(self._dis, ga, gb), _dis_flow(self._dis, gb, ga)
        self._pairs[key] = (flow_ab, flow_ba)
        if len(self._pairs) > _PAIR_CACHE_SIZE:
            self._pairs.popitem(last=False)
        return flow_ab, flow_ba, r0


def _groups(keys: np.ndarray) -> Iterator[tuple[int, np.ndarray]]:
    """``(key, positions)`` for each distinct key, positions in ascending order."""
    if keys.size == 0:
        return
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    starts = np.flatnonzero(np.diff(sorted_keys)) + 1
    for sel in np.split(order, starts):
        yield int(keys[sel[0]]), sel


def compose_rs(
    footage: Footage,
    t_start_ns: int,
    line_times_ns: np.ndarray,
    method: str = "nearest",
    by_column: bool = False,
    *,
    flow_preset: str = "medium",
    flow_margin_px: int | None = None,
    snap_ns: int = 1,
) -> np.ndarray:
    """One RS frame from GS footage: image line ``i`` sampled at ``t_start_ns + line_times_ns[i]``.

    ``line_times_ns`` are int64 offsets from ``t_start_ns``, one per image row (one per column with
    ``by_column``), e.g. ``timing.line_offset_ns(np.arange(height))``; absolute times from
    ``line_sample_times_ns`` go with ``t_start_ns=0``. The result has the footage's dtype and frame shape.
    Times outside the footage's span raise ``SourceError``.
    """
    composer = Composer(
        footage,
        method,
        by_column=by_column,
        flow_preset=flow_preset,
        flow_margin_px=flow_margin_px,
        snap_ns=snap_ns,
    )
    return composer.compose(np.int64(t_start_ns) + np.asarray(line_times_ns, dtype=np.int64))


def compose_frames(
    composer: Composer,
    line_times_fn: Callable[[int], np.ndarray],
    n_frames: int | None = None,
) -> Iterator[ComposedFrame]:
    """Consecutive RS frames whose line times (absolute ns) ``line_times_fn(n)`` gives for frame ``n``.

    Without ``n_frames`` the stream ends at the first frame that would run past the footage's end; with
    it, running out of footage raises ``SourceError``.
    """
    t_end = composer.footage.span_ns[1] + composer.snap_ns
    n = 0
    while n_frames is None or n < n_frames:
        times = np.asarray(line_times_fn(n), dtype=np.int64)
        if n_frames is None and int(times.max()) > t_end:
            return
        yield ComposedFrame(n, int(times.min()), times, composer.compose(times))
        n += 1


def compose_stream(
    footage: Footage,
    timing: LineTiming,
    readout: Readout | str = Readout.TOP_TO_BOTTOM,
    *,
    fps: FpsLike | None = None,
    start_ns: int = 0,
    method: str = "nearest",
    n_frames: int | None = None,
    flow_preset: str = "medium",
    flow_margin_px: int | None = None,
    snap_ns: int = 1,
    first_frame: int = 0,
) -> Iterator[ComposedFrame]:
    """RS frames a sensor with ``timing`` and ``readout`` would read from the scene the footage shows.

    Frame ``n`` starts at ``start_ns + round(n * 1e9 / fps)`` (``fps`` of the output; by default the
    sensor's own frame period, ``timing.frame_start_ns(n)``) and line ``k`` in readout order is sampled
    ``timing.line_offset_ns(k)`` later. E.g. 30 fps RS frames from 32,400 fps footage. ``first_frame``
    starts the stream at output frame ``first_frame`` (frame ``n`` yielded is output frame ``first_frame + n``,
    with its index), so one frame of a long stream is composed without the ones before it.
    """
    readout = Readout.parse(readout)
    composer = Composer(
        footage,
        method,
        by_column=readout.by_column,
        flow_preset=flow_preset,
        flow_margin_px=flow_margin_px,
        snap_ns=snap_ns,
    )
    out_fps: Fraction | None = None if fps is None else as_fps(fps, "output fps")

    def frame_start_ns(n: int) -> int:
        if out_fps is None:
            return timing.frame_start_ns(n, start_ns)
        num, den = out_fps.numerator, out_fps.denominator
        return int(start_ns) + (2 * n * NS_PER_S * den + num) // (2 * num)

    def line_times(n: int) -> np.ndarray:
        return line_sample_times_ns(frame_start_ns(first_frame + n), composer.n_lines, timing, readout)

    def frames() -> Iterator[ComposedFrame]:
        for frame in compose_frames(composer, line_times, n_frames):
            yield frame._replace(index=first_frame + frame.index)

    return frames()


def composition_error(composed: np.ndarray, reference: np.ndarray) -> dict[str, float]:
    """Mean and max absolute difference (in DN, the pixel values' own units) of a composed frame."""
    composed, reference = np.asarray(composed), np.asarray(reference)
    if composed.shape != reference.shape:
        raise ConfigError(f"composed shape {composed.shape!r} differs from reference {reference.shape!r}")
    diff = np.abs(composed.astype(np.float64) - reference.astype(np.float64))
    return {"mean_abs_err_dn": float(diff.mean()), "max_abs_err_dn": float(diff.max())}
