"""The realism study: do detectors trained on photographs find the rendered walkers, and is the scoring right?"""

from __future__ import annotations

import pytest
from rollcam.benchmarks.realism import (
    _best_recall_at_precision,
    _operating_point,
    _Tally,
    inside_fraction,
    iou,
    match_frame,
    realism,
)
from rollcam.common.errors import ConfigError


def test_iou_and_greedy_matching_in_score_order():
    assert iou((0, 0, 10, 10), (0, 0, 10, 10)) == 1.0
    assert iou((0, 0, 10, 10), (10, 0, 20, 10)) == 0.0
    assert iou((0, 0, 10, 10), (5, 0, 15, 10)) == pytest.approx(1 / 3)
    assert inside_fraction((0, 0, 10, 10), (0, 0, 100, 5)) == pytest.approx(0.5)
    kept = [(0, 0, 10, 20), (100, 0, 110, 20)]
    ignored = [(200, 0, 240, 80)]
    # listed out of score order: the better-scored duplicate takes the walker, the other is a false positive
    dets = [((1, 0, 11, 20), 1.5), ((0, 0, 10, 20), 2.0), ((201, 0, 211, 20), 1.0), ((500, 0, 510, 20), 0.5)]
    found, outcome = match_frame(dets, kept, ignored)
    assert found == [1, -1]
    # the third lies wholly inside an ignored (small, cut or occluded) walker's box: neither credited nor charged
    assert outcome == ["fp", "tp", "ignored", "fp"]


def test_operating_points_from_one_run():
    t = _Tally()
    kept = [(0, 0, 10, 20), (100, 0, 110, 20), (300, 0, 310, 20)]
    t.add([((0, 0, 10, 20), 0.9), ((500, 0, 510, 20), 0.8), ((100, 0, 110, 20), 0.6), ((700, 0, 710, 20), 0.2)],
          kept, [])
    low = _operating_point(t, 0.1)
    assert (low["recall"], low["precision"]) == (pytest.approx(2 / 3), 0.5)
    high = _operating_point(t, 0.7)
    assert (high["recall"], high["precision"]) == (pytest.approx(1 / 3), 0.5)
    best = _best_recall_at_precision(t, 0.6)
    assert best["threshold"] == 0.6 and best["recall"] == pytest.approx(2 / 3)
    assert best["precision"] == pytest.approx(2 / 3)
    assert _best_recall_at_precision(t, 1.0)["recall"] == pytest.approx(1 / 3)  # the first detection alone


def test_small_study_runs_and_reports_sane_fields():
    """One scene, one frame per camera, both default detectors: the numbers hang together."""
    calls = []
    res = realism(n_scenes=1, seed=0, frames_per_camera=1, progress=lambda done, total: calls.append(done))
    n = res["n_pedestrians"]
    assert n >= 5
    assert res["n_frames"] == len(calls) == 5
    for spec, rep in res["detectors"].items():
        a = rep["at_default"]
        assert 0.0 <= a["recall"] <= 1.0, spec
        assert a["n_detected"] == round(a["recall"] * n)
        assert a["precision"] is None or 0.0 <= a["precision"] <= 1.0
        assert sum(b["n"] for b in rep["recall_by_height_px"]["at_default"].values()) == n
        assert sum(b["n"] for b in rep["recall_by_time_of_day"]["at_default"].values()) == n
    assert res["settings"]["min_height_px"] == 128


def test_study_rejects_empty_sampling():
    with pytest.raises(ConfigError, match="n_scenes"):
        realism(n_scenes=0)
    with pytest.raises(ConfigError, match="unknown detector"):
        realism(detectors=["nosuch"], n_scenes=1)


@pytest.mark.slow
def test_detectors_find_the_unoccluded_daylight_walkers():
    res = realism()
    assert res["n_pedestrians"] >= 200
    assert res["detectors"]["hog"]["at_default"]["recall"] >= 0.7, res
    assert res["detectors"]["ssdlite?tiles=3x2&conf=0.05"]["at_default"]["recall"] >= 0.5, res
