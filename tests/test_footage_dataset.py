"""Labelled footage on disk through ``file:...&labels=`` and ``rollcam dataset --from-footage``, then eval."""

from __future__ import annotations

import json
from fractions import Fraction

import cv2
import numpy as np
import pytest
from hostile_files import npy_header_only, png_header_only
from rollcam.host import open_camera
from rollcam.host.cli import main
from rollcam.sim.instance_masks import render_masks, write_labelled_footage
from rollcam.sim.render.renderer import Renderer
from rollcam.sim.scenegen import make_street_scene

W, H = 96, 54
LINE_NS = 20_000
N_RS = 3  # composed frames, back to back: one per readout
OUT_FPS = Fraction(10**9, H * LINE_NS)


@pytest.fixture(scope="module")
def footage(tmp_path_factory):
    """rollcam's line-rate GS renders of a street as PNG frames with 16-bit instance masks and amodal masks."""
    root = tmp_path_factory.mktemp("footage")
    r = Renderer(make_street_scene(2, speed="fast", width=W, height=H, n_pedestrians=12), 4)
    frames, masks = write_labelled_footage(r, np.arange(N_RS * H, dtype=np.int64) * LINE_NS, root, durable=False)
    uri = f"file:{frames}?fps={10**9 // LINE_NS}&line_time_ns={LINE_NS}&out_fps={OUT_FPS}&labels={masks}"
    return r, frames, masks, uri


def test_file_source_composes_rs_labels_with_the_rs_frame(footage):
    r, _frames, _masks, uri = footage
    n_objects = 0
    with open_camera(uri) as src:
        assert src.composed_frames() == N_RS
        for n in range(N_RS):
            gs, rs = src.read_pair()
            times = rs.row_times_ns
            assert times.tolist() == (n * H * LINE_NS + np.arange(H) * LINE_NS).tolist()
            own = r.object_truth(r.render_lines(times, truth_only=True).truth, int(times[0]))
            assert {o.id: o.visible for o in rs.objects} == {o.id: o.visible for o in own}  # exact
            _vis, amodal = render_masks(r, times)
            for o in rs.objects:  # the RS box is the box of the RS frame's own amodal mask
                ys, xs = np.nonzero(amodal[o.id])
                assert o.box_rs == (xs.min(), ys.min(), xs.max() + 1, ys.max() + 1)
            gs_vis, _ = render_masks(r, np.full(H, times[0], np.int64))
            assert {o.id for o in gs.objects} == set(np.unique(gs_vis[gs_vis > 0]).tolist()) | {
                o.id for o in gs.objects if o.visible == 0}
            n_objects += len(rs.objects)
        assert src.read_pair() is None
    assert n_objects >= 10
    with open_camera(uri + "&start=2") as src:  # one composed frame without the ones before it
        _gs, rs = src.read_pair()
        assert rs.sequence == 2 and rs.row_times_ns[0] == 2 * H * LINE_NS


def test_dataset_from_footage_builds_the_rollcam_layout_and_evaluates(footage, tmp_path, capsys):
    _r, _frames, _masks, uri = footage
    out = tmp_path / "ds"
    assert main(["dataset", "--out", str(out), "--from-footage", uri, "--min-box", "1x1", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["pairs"] == N_RS and summary["subsets"] == ["footage_gs", "footage_rs"]
    card = json.loads((out / "dataset.json").read_text())
    assert card["config"]["source"] == uri
    for sub in ("footage_gs", "footage_rs"):
        assert (out / sub / "data.yaml").is_file()
        # 3 pairs: one per split, in time order
        assert [p.name for p in sorted((out / sub / "images" / "train").iterdir())] == ["f000000.png"]
    rec = json.loads((out / "records" / "footage" / "f000002.json").read_text())
    assert rec["split"] == "test" and rec["uri"] == uri + "&start=2&frames=1"
    with open_camera(rec["uri"]) as src:  # the record's URI reproduces the pair
        _gs, rs = src.read_pair()
    labelled = [o for o in rs.objects if o.visible >= 0.3]
    assert [o["box"] for o in rec["images"]["rs"]["objects"] if not o["ignore"]] == [list(o.box_rs) for o in labelled]
    yolo = (out / "footage_rs" / "labels" / "test" / "f000002.txt").read_text().splitlines()
    assert len(yolo) == len(labelled)
    img = cv2.imread(str(out / "footage_rs" / "images" / "test" / "f000002.png"))
    np.testing.assert_array_equal(img, rs.data)
    # rollcam eval reads it unchanged: ground-truth detections score 1.
    dets = [json.dumps({"image": im["file"], "detections": [{"box": o["box"], "score": 0.9, "cls": 0}
                                                           for o in im["objects"] if not o["ignore"]]})
            for p in sorted((out / "records").rglob("*.json")) for im in json.loads(p.read_text())["images"].values()]
    (tmp_path / "dets.jsonl").write_text("\n".join(dets) + "\n")
    assert main(["eval", str(out), "--detections", str(tmp_path / "dets.jsonl"), "--split", "train", "--json",
                 "--out", str(tmp_path / "ev")]) == 0
    doc = json.loads(capsys.readouterr().out)
    for shutter in ("gs", "rs"):
        assert doc["results"]["footage"][shutter]["mAP50"] == pytest.approx(1.0, abs=1e-6)
    # Rerun: nothing to redo.
    assert main(["dataset", "--out", str(out), "--from-footage", uri, "--min-box", "1x1", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["resumed"] == N_RS


@pytest.mark.parametrize("kind", ["png", "npy"])
def test_a_mask_declaring_a_huge_size_is_one_line_exit_2(footage, tmp_path, capsys, kind):
    """Issue 37 F2/F3: a PNG or .npy mask whose header declares 30000x30000 is refused from the header (main
    decoded it in full first, or ended in a MemoryError traceback) with one line and exit 2."""
    _r, _frames, masks, uri = footage
    bad = tmp_path / "masks"
    bad.mkdir()
    for p in sorted(masks.glob("*.png"))[:-1]:
        (bad / p.name).write_bytes(p.read_bytes())
    last = sorted(masks.glob("*.png"))[-1]
    if kind == "png":
        png_header_only(bad / last.name, 30000, 30000)
    else:
        npy_header_only(bad / last.with_suffix(".npy").name, (30000, 30000))
    out = tmp_path / "ds"
    assert main(["dataset", "--out", str(out), "--from-footage", uri.replace(str(masks), str(bad))]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("rollcam: error:") and "mask is 30000x30000" in err[0], err
    assert "from its header" in err[0] and not out.exists()


def test_bad_labels_fail_before_any_output(footage, tmp_path, capsys):
    _r, frames, masks, uri = footage
    bad = tmp_path / "masks"
    bad.mkdir()
    for p in sorted(masks.glob("*.png"))[:-1]:  # one frame's mask missing
        (bad / p.name).write_bytes(p.read_bytes())
    out = tmp_path / "ds"
    assert main(["dataset", "--out", str(out), "--from-footage", uri.replace(str(masks), str(bad))]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("rollcam: error:") and "no mask for footage frame" in err[0]
    assert str(bad) in err[0] and not out.exists()
    for p in sorted(masks.glob("*.png")):  # every frame there, but the last one of another size
        (bad / p.name).write_bytes(p.read_bytes())
    cv2.imwrite(str(bad / p.name), np.zeros((H, W // 2), np.uint16))
    assert main(["dataset", "--out", str(out), "--from-footage", uri.replace(str(masks), str(bad))]) == 2
    err = capsys.readouterr().err
    assert f"{p.name}' : mask is {W // 2}x{H}".replace("' :", "':") in err and not out.exists()
    assert main(["dataset", "--out", str(out), "--from-footage", uri, "--scenes", "5"]) == 2
    assert "--scenes describes emulated scenes" in capsys.readouterr().err
    assert main(["dataset", "--out", str(out), "--from-footage", f"file:{frames}?fps=50000&labels={masks}"]) == 2
    assert "composes no rolling-shutter frames" in capsys.readouterr().err
    assert not out.exists()
