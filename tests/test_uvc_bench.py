"""``rollcam bench uvc`` wiring: the document's shape and that every timed frame was recovered intact."""

from __future__ import annotations

import json

from rollcam.benchmarks.uvc import PAYLOADS, format_uvc, run_uvc_bench
from rollcam.host.cli import main


def test_uvc_bench_document():
    doc = run_uvc_bench(frames=2, path_frames=1)
    assert set(doc["codec"]) == set(PAYLOADS)
    for r in doc["codec"].values():
        assert r["frames_ok"] == 2 and r["pack_parse_mb_s"] > 0
    assert all(r["frames_ok"] >= 1 for r in doc["path"].values())
    assert doc["target"]["limit_mb_s"] == 1244.2 and isinstance(doc["target"]["pass"], bool)
    assert "iso_3072" in format_uvc(doc)
    y = doc["yuyv_conversion"]
    assert y["equal"] and y["rollcam_cpu_ms"] > 0 and y["opencv_cpu_ms"] > 0
    assert "1080p BGR->YUYV" in format_uvc(doc)


def test_bench_uvc_writes_json(tmp_path, capsys, monkeypatch):
    import rollcam.benchmarks.uvc as uvc

    real = uvc.run_uvc_bench
    monkeypatch.setattr(uvc, "run_uvc_bench", lambda: real(frames=1, path_frames=1))
    assert main(["bench", "uvc", "--json", "--out", str(tmp_path)]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert json.loads((tmp_path / "uvc.json").read_text())["codec"].keys() == printed["codec"].keys()
