"""The streaming studies (soak with a hog, memory soak, MJPEG serving) run end to end at small sizes; their
documents carry targets in the one shape ``--check`` reads. No speed is asserted here: that is the bench's."""

from __future__ import annotations

import pytest
from rollcam.benchmarks.studies import STUDIES


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/status") as f:
            return "zombie" not in f.read()
    except FileNotFoundError:
        return False


def test_soak_under_a_hog_counts_drops_as_a_fraction_and_ends_its_hog():
    from rollcam.benchmarks.soak import format_report, run_soak

    doc = run_soak(0.05, size=(640, 480), scene="flat", hog=True)
    hog = doc["config"]["hog"]
    assert hog["command"] == "yes > /dev/null" and not _alive(hog["pid"])
    assert set(doc["targets"]) == {"dropped_fraction"}
    assert doc["frames"] > 0 and 0 <= doc["dropped_fraction"] <= 1
    assert {"min_ahead", "remade", "late_skipped"} <= set(doc["pump"])
    assert "under a CPU hog" in format_report(doc)
    t = STUDIES["soak"].targets(doc)["dropped_fraction"]
    assert t["op"] == "<=" and t["limit"] == 0.001 and t["pass"] is (doc["dropped_fraction"] <= 0.001)


@pytest.mark.slow
def test_memory_soak_samples_the_emulator_and_stops_it():
    from rollcam.benchmarks.soak import format_memory_report, run_memory_soak

    doc = run_memory_soak(0.25, every_s=2, size=(640, 480))
    assert len(doc["rss_mb"]) >= 5 and all(mb > 50 for _, mb in doc["rss_mb"])
    assert doc["parts_read"] > 0
    assert doc["targets"]["rss_mb_max"]["value"] == doc["steady"]["max"]
    assert "curve" in format_memory_report(doc)


@pytest.mark.slow
def test_mjpeg_clients_each_get_the_stream_and_the_servers_drop_counts():
    from rollcam.benchmarks.mjpeg import serve_clients

    doc = serve_clients(3, 4.0, (640, 480))
    assert not doc["errors"] and doc["frames_encoded"] > 0
    assert len(doc["per_client"]) == 3
    for row in doc["per_client"]:
        assert row["parts"] > 0 and row["dropped_by_server"] is not None
    assert doc["encode_ms_mean"] > 0


def test_mjpeg_targets_read_in_the_one_shape():
    doc = {"targets": {"encode_ms_median": {"op": "<=", "limit": 10.0, "value": 4.2, "pass": True},
                       "client_drops": {"op": "==", "limit": 0, "value": 3, "pass": False}}}
    t = STUDIES["mjpeg"].targets(doc)
    assert t["encode_ms_median"]["pass"] is True and t["client_drops"]["pass"] is False
    assert all(set(v) == {"value", "op", "limit", "pass"} for v in t.values())
