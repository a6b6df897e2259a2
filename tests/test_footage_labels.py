"""RS labels composed from per-frame footage labels: exact from rollcam's line-rate GS renders, bounded from boxes."""

from __future__ import annotations

import itertools
from fractions import Fraction

import numpy as np
import pytest
from rollcam.sim.compose import line_sources
from rollcam.sim.footage import Footage
from rollcam.sim.footage_labels import BoxLabels, LabelTrack, MaskLabels, TruthLabels, compose_truth
from rollcam.sim.instance_masks import render_masks
from rollcam.sim.render.renderer import Renderer
from rollcam.sim.scenegen import make_street_scene

W, H = 160, 90
LINE_NS = 20_000  # footage at the line rate: 50,000 fps, frame k at k * LINE_NS exactly
T0_NS = 3_000_000


def _renderer(seed: int, cam: int, speed: str | float = "fast") -> Renderer:
    return Renderer(make_street_scene(seed, speed=speed, width=W, height=H, n_pedestrians=12), cam)


def _gs(r: Renderer, t_ns: int, by_column: bool = False):
    n = W if by_column else H
    return r.render_lines(np.full(n, t_ns, np.int64), by_column=by_column, truth_only=True).truth


def _footage(n_frames: int, step_ns: int) -> Footage:
    """Blank frames standing in for the footage's pixels: labels composition reads only its clock."""
    return Footage.from_frames(np.zeros((n_frames, H, W), np.uint8), Fraction(10**9, step_ns))


def _truth_key(objs):
    return {o.id: (o.box_gs, o.box_rs, o.visible) for o in objs}


@pytest.mark.parametrize(("seed", "cam", "by_column"), [(2, 0, False), (2, 4, False), (5, 1, False), (2, 4, True)])
def test_instance_masks_are_the_renderers_pixel_truth(seed, cam, by_column):
    """Per line, an actor's amodal mask pixels are LineTruth.area and its visible pixels LineTruth.visible."""
    r = _renderer(seed, cam)
    n = W if by_column else H
    checked = 0
    for times in (np.full(n, T0_NS, np.int64), T0_NS + np.arange(n, dtype=np.int64) * LINE_NS * 7):
        truth = r.render_lines(times, by_column=by_column, truth_only=True).truth
        vis, amodal = render_masks(r, times, by_column=by_column)
        axis = 0 if by_column else 1
        for o, oid in enumerate(r.actor_ids):
            area = amodal[oid].sum(axis=axis) if oid in amodal else np.zeros(n, np.int64)
            np.testing.assert_array_equal(area, truth.area[o])
            np.testing.assert_array_equal((vis == oid).sum(axis=axis), truth.visible[o])
            checked += int(truth.area[o].sum() > 0)
    assert checked >= 2


@pytest.mark.parametrize("by_column", [False, True])
def test_truth_labels_at_line_rate_give_exactly_rollcams_rs_truth(by_column):
    """rollcam's per-line truth of line-rate GS frames, composed, equals the RS frame's own truth bit for bit."""
    n = W if by_column else H
    rs_times = T0_NS + np.arange(n, dtype=np.int64) * LINE_NS
    n_frames = T0_NS // LINE_NS + n + 1
    fp = _footage(n_frames, LINE_NS)
    src = line_sources(fp, rs_times)
    objects = 0
    for seed, cam in ((2, 0), (2, 1), (2, 4), (5, 3)):
        r = _renderer(seed, cam)
        track = LabelTrack.from_frames([TruthLabels(r.actor_ids, _gs(r, k * LINE_NS, by_column))
                                        for k in range(n_frames)], (W, H))
        ref_k = T0_NS // LINE_NS
        got = compose_truth(track, src, ref_k, by_column=by_column)
        rs = r.render_lines(rs_times, by_column=by_column, truth_only=True).truth
        want = r.object_truth(rs, T0_NS, by_column)
        assert _truth_key(got) == _truth_key(want)
        objects += sum(o.box_rs is not None for o in want)
    assert objects >= 15  # not vacuous: moving walkers in view


def test_mask_labels_at_line_rate_give_the_rs_masks_labels_and_rollcams_visibility():
    """Masks of line-rate GS frames, composed, give exactly the labels of the RS frame's own masks; visibility
    equals rollcam's exactly (same pixel counts per line), boxes are rollcam's to within its sub-pixel slivers."""
    rs_times = T0_NS + np.arange(H, dtype=np.int64) * LINE_NS
    fp = _footage(H + T0_NS // LINE_NS, LINE_NS)
    src = line_sources(fp, rs_times)
    n_obj = n_box_equal = 0
    for seed, cam in ((2, 0), (2, 4), (5, 1)):
        r = _renderer(seed, cam)
        frames = [MaskLabels(*render_masks(r, np.full(H, k * LINE_NS, np.int64))) for k in range(len(fp))]
        got = {o.id: o for o in compose_truth(LabelTrack.from_frames(frames, (W, H)), src, T0_NS // LINE_NS)}
        rs_masks = MaskLabels(*render_masks(r, rs_times))
        direct = compose_truth(LabelTrack.from_frames([rs_masks] * len(fp), (W, H)), src, T0_NS // LINE_NS)
        assert {k: (v.box_rs, v.visible) for k, v in got.items()} == {o.id: (o.box_rs, o.visible) for o in direct}
        rs_truth = r.render_lines(rs_times, truth_only=True).truth
        want = r.object_truth(rs_truth, T0_NS)
        for o in want:
            if o.box_rs is None:
                continue
            g = got.get(o.id)
            covered = np.flatnonzero(rs_truth.area[r.actor_ids.index(o.id)] > 0)
            if g is None or g.box_rs is None:  # a sliver covering no pixel centre on any line
                assert covered.size == 0
                continue
            n_obj += 1
            assert g.visible == o.visible
            # Across lines: exactly the lines where rollcam counts covered pixels. Along lines: rollcam's extent
            # rounded to pixel centres, less at most one pixel where a part's span covers no centre.
            assert (g.box_rs[1], g.box_rs[3]) == (covered[0], covered[-1] + 1)
            x0, x1 = np.ceil(o.box_rs[0] - 0.5), np.ceil(o.box_rs[2] - 0.5)
            assert x0 <= g.box_rs[0] <= x0 + 1 and x1 - 1 <= g.box_rs[2] <= x1
            n_box_equal += (g.box_rs[0], g.box_rs[2]) == (x0, x1) and (o.box_rs[1], o.box_rs[3]) == g.box_rs[1::2]
    assert n_obj >= 10 and n_box_equal >= n_obj // 3


def _box_frames(r: Renderer, times_ns: list[int]) -> list[BoxLabels]:
    out = []
    for t in times_ns:
        gt = _gs(r, t)
        boxes = gt.boxes()
        keep = [i for i, b in enumerate(boxes) if b is not None]
        out.append(BoxLabels.of([r.actor_ids[i] for i in keep], [boxes[i] for i in keep],
                                gt.visible_fraction()[keep]))
    return out


def test_box_labels_hold_the_stated_bound():
    """Boxes interpolated per line: each RS edge within v / (2 fps) (+1 line across lines) of rollcam's RS box,
    outward by at most the object's own RS skew v * h * line_time more, at footage rates from the line rate down
    to two frames per RS frame."""
    rs_times = np.arange(H, dtype=np.int64) * LINE_NS
    worst_ratio, worst_err, n = 0.0, 0.0, 0
    for seed, cam, speed in ((2, 0, "fast"), (2, 4, "fast"), (5, 1, 30.0), (5, 3, 300.0)):
        r = _renderer(seed, cam, speed)
        want = {o.id: o for o in r.object_truth(r.render_lines(rs_times, truth_only=True).truth, 0)}
        dense = [dict(zip(r.actor_ids, _gs(r, k * LINE_NS).boxes(), strict=True)) for k in range(H)]
        for m in (1, 3, 9, 30, 89):
            n_frames = (H - 2) // m + 2
            step_ns = m * LINE_NS
            track = LabelTrack.from_frames(_box_frames(r, [k * step_ns for k in range(n_frames)]), (W, H))
            got = {o.id: o for o in compose_truth(track, line_sources(_footage(n_frames, step_ns), rs_times), 0)}
            for oid, o in want.items():
                if o.box_rs is None:
                    continue
                # Edge speeds (px/s) from the GS boxes at the line rate; across lines over the footage step,
                # since those edges are whole lines.
                seq = [d[oid] for d in dense]
                pairs = [(a, b) for a, b in zip(seq, seq[min(m, H - 1):], strict=False) if a and b]
                v_along = max((abs(b[e] - a[e]) for a, b in itertools.pairwise(seq) if a and b
                               for e in (0, 2)), default=0.0) / (LINE_NS * 1e-9)
                v_across = max((abs(b[e] - a[e]) for a, b in pairs for e in (1, 3)), default=0.0) / (step_ns * 1e-9)
                eps = v_along * step_ns * 1e-9 / 2
                eps_y = v_across * step_ns * 1e-9 / 2 + 1
                skew = v_along * (o.box_rs[3] - o.box_rs[1]) * LINE_NS * 1e-9
                g = got.get(oid)
                if g is None or g.box_rs is None:  # gone between frames: only a sliver under the bound
                    assert o.box_rs[2] - o.box_rs[0] <= eps + 1e-9
                    continue
                out_x = (o.box_rs[0] - g.box_rs[0], g.box_rs[2] - o.box_rs[2])  # outward overshoot
                for e in out_x:
                    assert -eps - 1e-9 <= e <= eps + skew + 1e-9, (seed, cam, m, oid, o.box_rs, g.box_rs)
                for e in (abs(o.box_rs[1] - g.box_rs[1]), abs(o.box_rs[3] - g.box_rs[3])):
                    assert e <= eps_y + 1e-9, (seed, cam, m, oid, o.box_rs, g.box_rs)
                worst_err = max(worst_err, *map(abs, out_x))
                if eps + skew > 0:
                    worst_ratio = max(worst_ratio, max(abs(e) for e in out_x) / (eps + skew))
                n += 1
    assert n >= 100 and worst_err > 0.5 and worst_ratio > 0.5  # the bound is exercised and not loose


def test_linear_method_at_line_rate_is_exact_too():
    """Under linear/flow every line at a frame's time is that frame's line: labels stay exact."""
    r = _renderer(2, 4)
    rs_times = np.arange(H, dtype=np.int64) * LINE_NS
    fp = _footage(H, LINE_NS)
    src = line_sources(fp, rs_times)
    track = LabelTrack.from_frames([TruthLabels(r.actor_ids, _gs(r, k * LINE_NS)) for k in range(H)], (W, H))
    assert src.exact.all()
    assert _truth_key(compose_truth(track, src, 0, blended=~src.exact)) == _truth_key(compose_truth(track, src, 0))
    want = r.object_truth(r.render_lines(rs_times, truth_only=True).truth, 0)
    assert _truth_key(compose_truth(track, src, 0)) == _truth_key(want)
