"""Per-frame object labels of global-shutter footage, and the rolling-shutter labels composed from them.

A footage frame's labels are either *line labels* (each instance's extent on every image line with its
covered and visible pixel counts: from instance masks, ``MaskLabels``, or from rollcam's own per-line truth,
``TruthLabels``) or *box labels* (one box per instance, ``BoxLabels``). ``compose_truth`` builds the RS
labels of a composed frame line by line from the same footage frames its image lines come from
(``rollcam.sim.compose.line_sources``), into a ``LineTruth``, so boxes and visibility are computed by the
renderer's own code (``LineTruth.boxes``, ``visible_fraction``):

- line labels are exact: a line copied from footage frame k (every line under ``nearest``; lines at a frame's
  time under ``linear``/``flow``) has frame k's extent on that line. A line the image blends between frames a
  and b gets the extents interpolated at the same fraction (the box bound below then applies to it).
- box labels: line i's box is the instance's box linearly interpolated between the frames bracketing the line's
  time, and the line belongs to the instance when its centre lies in that box. With footage at ``fps`` and box
  edges moving at most ``v`` px/s, each interpolated edge is within ``v / (2 fps)`` px of the true box at that
  instant (``2 w (1 - w) v / fps`` at fraction ``w``), so the RS box's edges are within that (plus one line for
  the line-centre rule across lines) of the RS box of the true boxes. That box contains the object's true RS box
  (a box does not say which lines hold its widest part) and exceeds it along lines by at most
  ``v_line * h * line_time``: the object's own RS skew over its ``h`` lines.

An instance is matched across frames by its id; one present in only one of a line's two frames is on that line
when that frame is the nearest one (it appears or leaves at the midpoint).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from rollcam.common.errors import ConfigError, SourceError

from .compose import LineSources
from .frame import ObjectTruth
from .render.result import LineTruth, object_truths


@dataclass(frozen=True)
class MaskLabels:
    """Instance masks of one frame: ``visible`` (H x W ints, 0 background, else the id of the instance that
    pixel shows), and optionally ``amodal`` (id -> H x W bool: every pixel the instance covers, hidden or not).

    Without ``amodal`` an instance covers exactly the pixels it shows (visibility 1). Extents are in whole
    pixels: an instance's extent on a line runs from its first to one past its last pixel there.
    """

    visible: np.ndarray
    amodal: Mapping[int, np.ndarray] | None = None
    _cache: dict[bool, tuple[np.ndarray, LineTruth]] = field(default_factory=dict, repr=False, compare=False)

    kind = "lines"

    @property
    def ids(self) -> np.ndarray:
        """Instance ids in this frame, ascending."""
        return self.line_truth(False)[0]

    def line_truth(self, by_column: bool) -> tuple[np.ndarray, LineTruth]:
        """(ids, per-line truth) with lines along rows, or columns when ``by_column``."""
        hit = self._cache.get(by_column)
        if hit is None:
            hit = self._cache[by_column] = _mask_truth(self.visible, self.amodal, by_column)
        return hit


def _mask_truth(visible: np.ndarray, amodal: Mapping[int, np.ndarray] | None,
                by_column: bool) -> tuple[np.ndarray, LineTruth]:
    vis = visible.T if by_column else visible
    ids = np.unique(vis)
    ids = ids[ids != 0].astype(np.int64)
    if amodal:
        ids = np.union1d(ids, np.fromiter(amodal, np.int64, len(amodal)))
    n_lines, n_along = vis.shape
    gt = LineTruth.empty(len(ids), n_lines, by_column)
    for i, oid in enumerate(ids.tolist()):
        shown = vis == oid
        cover = shown
        if amodal and oid in amodal:
            cover = amodal[oid].T if by_column else amodal[oid]
        rows = np.flatnonzero(cover.any(axis=1))
        if rows.size == 0:
            continue
        sub = cover[rows]
        gt.left[i, rows] = np.argmax(sub, axis=1)
        gt.right[i, rows] = n_along - np.argmax(sub[:, ::-1], axis=1)
        gt.area[i, rows] = sub.sum(axis=1)
        gt.visible[i, rows] = shown[rows].sum(axis=1)
    return ids, gt


@dataclass(frozen=True)
class TruthLabels:
    """rollcam's own per-line truth of a footage frame (a ``LineTruth`` of one orientation, its ids)."""

    ids_: Sequence[int]
    truth: LineTruth

    kind = "lines"

    @property
    def ids(self) -> np.ndarray:
        """Instance ids, in the truth's actor order."""
        return np.asarray(self.ids_, np.int64)

    def line_truth(self, by_column: bool) -> tuple[np.ndarray, LineTruth]:
        """(ids, truth); only the orientation it was rendered in."""
        if by_column != self.truth.transposed:
            raise ConfigError("per-line truth was rendered " + ("by column" if self.truth.transposed else "by row")
                              + "; compose it with the same readout orientation")
        return self.ids, self.truth


@dataclass(frozen=True)
class BoxLabels:
    """Boxes of one frame: ``boxes`` (n x 4, x0 y0 x1 y1 px, x1/y1 exclusive) of instances ``ids``, with the
    fraction of each that shows (``visible``, 1 when the format has none)."""

    ids: np.ndarray
    boxes: np.ndarray
    visible: np.ndarray

    kind = "boxes"

    @classmethod
    def of(cls, ids: Sequence[int], boxes: Sequence[Sequence[float]], visible: Sequence[float] | None = None
           ) -> BoxLabels:
        """Box labels from plain sequences (ids unique)."""
        ids_a = np.asarray(ids, np.int64).reshape(-1)
        b = np.asarray(boxes, np.float64).reshape(-1, 4)
        v = np.ones(len(ids_a)) if visible is None else np.asarray(visible, np.float64).reshape(-1)
        if not len(ids_a) == len(b) == len(v):
            raise ConfigError(f"{len(ids_a)} ids, {len(b)} boxes and {len(v)} visible fractions do not match")
        order = np.argsort(ids_a, kind="stable")
        return cls(ids_a[order], b[order], v[order])


FrameLabels = MaskLabels | TruthLabels | BoxLabels


class LabelTrack:
    """Labels of every frame of one footage (frame k's labels by ``track[k]``), all of one kind.

    ``loader(k)`` reads frame k's labels (a few are cached); ``classes`` maps instance id to class name
    (default ``default_class``); ``size`` is the footage frame size (width, height) the labels are in.
    """

    def __init__(self, name: str, n_frames: int, size: tuple[int, int], kind: str,
                 loader: Callable[[int], FrameLabels], classes: dict[int, str] | None = None,
                 default_class: str = "person", cache_frames: int = 8) -> None:
        self.name, self.n_frames, self.size, self.kind = name, int(n_frames), size, kind
        self._loader = loader
        self.classes = classes if classes is not None else {}  # a reader may fill it as frames load
        self.default_class = default_class
        self._cache: OrderedDict[int, FrameLabels] = OrderedDict()
        self._cache_frames = max(1, cache_frames)

    @classmethod
    def from_frames(cls, frames: Sequence[FrameLabels], size: tuple[int, int],
                    classes: dict[int, str] | None = None, name: str = "<labels>") -> LabelTrack:
        """A track of labels already in memory (one per footage frame, all of one kind)."""
        kinds = {f.kind for f in frames}
        if len(kinds) > 1:
            raise ConfigError(f"{name!r}: frames mix label kinds {sorted(kinds)}")
        return cls(name, len(frames), size, kinds.pop() if kinds else "boxes", lambda k: frames[k], classes)

    def __len__(self) -> int:
        return self.n_frames

    def __getitem__(self, k: int) -> FrameLabels:
        hit = self._cache.get(k)
        if hit is not None:
            self._cache.move_to_end(k)
            return hit
        labels = self._loader(k)
        if labels.kind != self.kind:
            raise SourceError(f"{self.name!r}: frame {k} has {labels.kind} labels, the others {self.kind}")
        self._cache[k] = labels
        if len(self._cache) > self._cache_frames:
            self._cache.popitem(last=False)
        return labels

    def class_of(self, oid: int) -> str:
        """Class name of instance ``oid``."""
        return self.classes.get(int(oid), self.default_class)

    def check_footage(self, n_frames: int, size: tuple[int, int]) -> None:
        """Refuse labels for another footage (frame count or size)."""
        if self.n_frames != n_frames:
            raise SourceError(f"{self.name!r}: labels hold {self.n_frames} frames, the footage {n_frames}")
        if tuple(self.size) != tuple(size):
            raise SourceError(f"{self.name!r}: labels are for {self.size[0]}x{self.size[1]} frames, the footage is "
                              f"{size[0]}x{size[1]}")


# ---------------------------------------------------------------------------------------------- composition
def frame_truth(track: LabelTrack, k: int) -> tuple[ObjectTruth, ...]:
    """The objects of footage frame ``k`` as a GS frame shows them (``box_rs`` = ``box_gs``)."""
    lab = track[k]
    w, h = track.size
    if lab.kind == "boxes":
        assert isinstance(lab, BoxLabels)
        out = []
        for oid, box, vis in zip(lab.ids.tolist(), lab.boxes, lab.visible.tolist(), strict=True):
            b = _clip_box(box, w, h)
            if b is not None:
                out.append(ObjectTruth(oid, track.class_of(oid), b, b, float(vis), 0.0))
        return tuple(out)
    ids, gt = lab.line_truth(False)  # type: ignore[union-attr]
    return tuple(ObjectTruth(o.id, o.cls, o.box_gs, o.box_gs, o.visible, 0.0)
                 for o in object_truths(gt, gt, ids.tolist(), [track.class_of(i) for i in ids], [0.0] * len(ids)))


def _clip_box(box: np.ndarray, w: int, h: int) -> tuple[float, float, float, float] | None:
    x0, y0 = max(float(box[0]), 0.0), max(float(box[1]), 0.0)
    x1, y1 = min(float(box[2]), float(w)), min(float(box[3]), float(h))
    return (x0, y0, x1, y1) if x1 > x0 and y1 > y0 else None


def compose_truth(track: LabelTrack, src: LineSources, reference_k: int, *, by_column: bool = False,
                  blended: np.ndarray | None = None) -> tuple[ObjectTruth, ...]:
    """The objects of an RS frame composed line by line from the footage frames ``src`` names.

    ``blended`` marks the lines the image blended between two frames (None: none, as under ``nearest``); every
    other line comes from ``src.exact_k`` where ``src.exact``, else ``src.nearest``. ``box_gs`` is each
    object's box in footage frame ``reference_k`` (the frame at the RS frame's reference instant).
    """
    n_lines = src.a.shape[0]
    blended = np.zeros(n_lines, bool) if blended is None else blended
    frame_of = np.where(src.exact, src.exact_k, src.nearest)
    used = np.unique(np.concatenate([frame_of, src.a[blended], src.b[blended], [reference_k]]))
    ids = np.unique(np.concatenate([track[int(k)].ids for k in used] + [np.zeros(0, np.int64)]))
    if track.kind == "boxes":
        rs, gs = _box_lines(track, src, frame_of, blended, ids, by_column, reference_k)
    else:
        rs, gs = _mask_lines(track, src, frame_of, blended, ids, by_column, reference_k)
    classes = [track.class_of(i) for i in ids.tolist()]
    objs = object_truths(rs, gs, ids.tolist(), classes, [0.0] * len(ids))
    if track.kind == "boxes":  # GS boxes are the reference frame's own boxes, not their line-quantised form
        ref = {o.id: o for o in frame_truth(track, reference_k)}
        objs = tuple(ObjectTruth(o.id, o.cls, ref[o.id].box_gs if o.id in ref else None, o.box_rs, o.visible,
                                 o.speed_mps) for o in objs if o.box_rs is not None or o.id in ref)
    return objs


def _scatter(ids: np.ndarray, lab_ids: np.ndarray) -> np.ndarray:
    return np.searchsorted(ids, lab_ids)


def _lines_of(track: LabelTrack, k: int, ids: np.ndarray, by_column: bool) -> LineTruth:
    """Frame ``k``'s per-line truth with rows in ``ids`` order (instances absent from it empty)."""
    lab_ids, gt = track[k].line_truth(by_column)  # type: ignore[union-attr]
    n_lines = gt.left.shape[1]
    out = LineTruth.empty(len(ids), n_lines, by_column)
    at = _scatter(ids, lab_ids)
    out.left[at], out.right[at], out.area[at], out.visible[at] = gt.left, gt.right, gt.area, gt.visible
    return out


def _mask_lines(track: LabelTrack, src: LineSources, frame_of: np.ndarray, blended: np.ndarray, ids: np.ndarray,
                by_column: bool, reference_k: int) -> tuple[LineTruth, LineTruth]:
    n_lines = frame_of.shape[0]
    rs = LineTruth.empty(len(ids), n_lines, by_column)
    frames: dict[int, LineTruth] = {}

    def lines(k: int) -> LineTruth:
        if k not in frames:
            frames[k] = _lines_of(track, k, ids, by_column)
        return frames[k]

    for k in np.unique(frame_of).tolist():
        sel = np.flatnonzero(frame_of == k)
        ft = lines(k)
        if ft.left.shape[1] != n_lines:
            raise SourceError(f"{track.name!r}: frame {k}'s labels have {ft.left.shape[1]} lines, the frame {n_lines}")
        for name in ("left", "right", "area", "visible"):
            getattr(rs, name)[:, sel] = getattr(ft, name)[:, sel]
    for i in np.flatnonzero(blended).tolist():
        la, lb, w = lines(int(src.a[i])), lines(int(src.b[i])), float(src.w[i])
        both = ~np.isnan(la.left[:, i]) & ~np.isnan(lb.left[:, i])
        rs.left[both, i] = (1 - w) * la.left[both, i] + w * lb.left[both, i]
        rs.right[both, i] = (1 - w) * la.right[both, i] + w * lb.right[both, i]
    return rs, lines(int(reference_k))


def _box_lines(track: LabelTrack, src: LineSources, frame_of: np.ndarray, blended: np.ndarray, ids: np.ndarray,
               by_column: bool, reference_k: int) -> tuple[LineTruth, LineTruth]:
    """Per-line truth of box labels: each line's box interpolated at the line's time (see the module doc)."""
    w_img, h_img = track.size
    n_lines = frame_of.shape[0]
    n_along = h_img if by_column else w_img
    # Every line interpolates between its bracketing frames; a line at a frame's time uses that frame alone.
    ka = np.where(src.exact, src.exact_k, src.a)
    kb = np.where(src.exact, src.exact_k, src.b)
    wt = np.where(src.exact, 0.0, src.w)
    boxes_a = np.full((len(ids), n_lines, 4), np.nan)
    boxes_b = np.full((len(ids), n_lines, 4), np.nan)
    vis_a = np.full((len(ids), n_lines), np.nan)
    vis_b = np.full((len(ids), n_lines), np.nan)
    for k in np.unique(np.concatenate([ka, kb])).tolist():
        lab = track[k]
        assert isinstance(lab, BoxLabels)
        at = _scatter(ids, lab.ids)
        for kk, boxes, vis in ((ka, boxes_a, vis_a), (kb, boxes_b, vis_b)):
            sel = np.flatnonzero(kk == k)
            if sel.size:
                boxes[np.ix_(at, sel)] = lab.boxes[:, None, :]
                vis[np.ix_(at, sel)] = lab.visible[:, None]
    in_a, in_b = ~np.isnan(boxes_a[..., 0]), ~np.isnan(boxes_b[..., 0])
    near_a = (wt <= 0.5)[None, :]
    w3 = wt[None, :, None]
    one = np.where((in_a & near_a)[..., None], boxes_a, np.where((in_b & ~near_a)[..., None], boxes_b, np.nan))
    box = np.where((in_a & in_b)[..., None], (1 - w3) * boxes_a + w3 * boxes_b, one)
    vis = np.where(in_a & in_b, (1 - wt) * vis_a + wt * vis_b, np.where(in_a & near_a, vis_a, vis_b))
    rs = _boxes_to_lines(box, vis, n_along, by_column)
    ref = track[int(reference_k)]
    assert isinstance(ref, BoxLabels)
    at = _scatter(ids, ref.ids)
    gbox = np.full((len(ids), n_lines, 4), np.nan)
    gvis = np.zeros((len(ids), n_lines))
    gbox[at] = ref.boxes[:, None, :]
    gvis[at] = ref.visible[:, None]
    return rs, _boxes_to_lines(gbox, gvis, n_along, by_column)


def _boxes_to_lines(box: np.ndarray, vis: np.ndarray, n_along: int, by_column: bool) -> LineTruth:
    """A LineTruth of boxes ``(instances, lines, 4)`` (NaN: absent): a line is in a box when its centre is."""
    n_obj, n_lines = box.shape[:2]
    lo_a, hi_a, lo_l, hi_l = ((box[..., 1], box[..., 3], box[..., 0], box[..., 2]) if by_column
                              else (box[..., 0], box[..., 2], box[..., 1], box[..., 3]))
    centre = np.arange(n_lines)[None, :] + 0.5
    with np.errstate(invalid="ignore"):
        on = (lo_l <= centre) & (centre < hi_l) & (hi_a > 0) & (lo_a < n_along)
    gt = LineTruth.empty(n_obj, n_lines, by_column)
    gt.area = np.zeros((n_obj, n_lines))
    gt.visible = np.zeros((n_obj, n_lines))
    left, right = np.clip(lo_a, 0.0, n_along), np.clip(hi_a, 0.0, n_along)
    gt.left[on], gt.right[on] = left[on], right[on]
    pix = np.clip(np.ceil(right - 0.5) - np.ceil(left - 0.5), 0, None)
    gt.area[on] = pix[on]
    gt.visible[on] = pix[on] * np.nan_to_num(vis[on], nan=1.0)
    return gt
