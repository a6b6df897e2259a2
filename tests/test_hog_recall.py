"""The walkers must look enough like people for OpenCV's stock HOG people detector to find them."""

from __future__ import annotations

import pytest
from rollcam.benchmarks.hog_recall import hog_recall, iou, match_frame
from rollcam.common.errors import ConfigError


def test_iou_and_greedy_matching():
    assert iou((0, 0, 10, 10), (0, 0, 10, 10)) == 1.0
    assert iou((0, 0, 10, 10), (10, 0, 20, 10)) == 0.0
    assert iou((0, 0, 10, 10), (5, 0, 15, 10)) == pytest.approx(1 / 3)
    kept = [(0, 0, 10, 20), (100, 0, 110, 20)]
    ignored = [(200, 0, 210, 20)]
    dets = [((0, 0, 10, 20), 2.0), ((1, 0, 11, 20), 1.5), ((201, 0, 211, 20), 1.0), ((500, 0, 510, 20), 0.5)]
    found, fp, n_ign = match_frame(dets, kept, ignored)
    assert found == [True, False]
    assert (fp, n_ign) == (2, 1)  # the duplicate on the first walker and the detection on nothing


def test_small_study_runs_and_reports_sane_fields():
    """One scene, one frame per camera: the study runs end to end and its numbers hang together."""
    calls = []
    res = hog_recall(n_scenes=1, seed=0, frames_per_camera=1, progress=lambda done, total: calls.append(done))
    n = res["n_pedestrians"]
    assert n >= 5
    assert 0.0 <= res["recall"] <= 1.0
    assert res["n_detected"] == round(res["recall"] * n)
    assert res["precision"] is None or 0.0 <= res["precision"] <= 1.0
    assert res["n_detections"] >= res["n_detected"] + res["n_false_positives"]
    assert sum(b["n"] for b in res["recall_by_height_px"].values()) == n
    assert sum(t["n"] for t in res["recall_by_time_of_day"].values()) == n
    assert res["n_frames"] == len(calls) == 5
    assert res["settings"]["min_height_px"] == 128


def test_study_rejects_empty_sampling():
    with pytest.raises(ConfigError, match="n_scenes"):
        hog_recall(n_scenes=0)


@pytest.mark.slow
def test_hog_finds_at_least_half_of_unoccluded_daylight_walkers():
    res = hog_recall()
    assert res["n_pedestrians"] >= 200
    assert res["recall"] >= 0.5, res
