"""Footage label files: instance masks, COCO (boxes, RLE, polygons), MOT, YOLO; every bad file gets one clear error."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from hostile_files import npy_header_only, png_header_only
from rollcam.common.errors import SourceError
from rollcam.sim.label_formats import detect_format, load_labels, rle_decode

W, H = 32, 24


def _masks(folder: Path, n: int, dtype=np.uint16, ids=(3, 300)) -> list[np.ndarray]:
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for k in range(n):
        m = np.zeros((H, W), dtype)
        m[2 + k:10 + k, 4:9] = ids[0]
        if len(ids) > 1:
            m[12:20, 10 + k:20 + k] = ids[1]
        cv2.imwrite(str(folder / f"m{k}.png"), m)
        out.append(m)
    return out


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_instance_masks_8_and_16_bit(tmp_path, dtype):
    ids = (3, 200) if dtype == np.uint8 else (3, 300)
    _masks(tmp_path / "m", 3, dtype, ids)
    assert detect_format(tmp_path / "m") == "masks"
    track = load_labels(tmp_path / "m", n_frames=3, size=(W, H))
    lab_ids, gt = track[1].line_truth(False)
    assert lab_ids.tolist() == list(ids)
    assert gt.boxes() == [(4.0, 3.0, 9.0, 11.0), (11.0, 12.0, 21.0, 20.0)]
    assert gt.visible_fraction().tolist() == [1.0, 1.0]
    _, cols = track[1].line_truth(True)  # column readout: lines are columns
    assert cols.boxes() == gt.boxes()


def test_amodal_masks_give_visibility_and_must_contain_the_visible_pixels(tmp_path):
    _masks(tmp_path / "m", 1, ids=(3,))
    am = np.zeros((H, W), np.uint8)
    am[2:14, 4:9] = 255  # 12 rows x 5 covered, 8 rows shown
    (tmp_path / "m" / "amodal" / "m0").mkdir(parents=True)
    cv2.imwrite(str(tmp_path / "m" / "amodal" / "m0" / "3.png"), am)
    track = load_labels(tmp_path / "m", n_frames=1, size=(W, H))
    _, gt = track[0].line_truth(False)
    assert gt.boxes() == [(4.0, 2.0, 9.0, 14.0)]
    assert gt.visible_fraction()[0] == pytest.approx(8 / 12)
    am[:] = 0
    cv2.imwrite(str(tmp_path / "m" / "amodal" / "m0" / "3.png"), am)
    with pytest.raises(SourceError, match=r"m0\.png.*id 3 shows outside its amodal mask"):
        load_labels(tmp_path / "m", n_frames=1, size=(W, H))[0]


@pytest.mark.parametrize(("case", "message"), [
    ("count", r"holds 2 mask files, the footage 3 frames"),
    ("size", r"m1\.png'?: mask is 16x24, the footage 32x24"),
    ("colour", r"m1\.png'?: an instance mask must be one channel"),
    ("corrupt", r"m1\.png'?: cannot decode mask image"),
    ("amodal_missing", r"m0\.png'?: instance id 3 shows but has no amodal mask"),
])
def test_bad_masks_name_the_file_and_problem(tmp_path, case, message):
    _masks(tmp_path / "m", 3)
    m1 = tmp_path / "m" / "m1.png"
    if case == "count":
        m1.unlink()
    elif case == "size":
        cv2.imwrite(str(m1), np.zeros((H, 16), np.uint16))
    elif case == "colour":
        cv2.imwrite(str(m1), np.zeros((H, W, 3), np.uint8))
    elif case == "corrupt":
        m1.write_bytes(b"\x89PNG not really")
    else:
        (tmp_path / "m" / "amodal" / "m0").mkdir(parents=True)
        cv2.imwrite(str(tmp_path / "m" / "amodal" / "m0" / "300.png"), np.full((H, W), 255, np.uint8))
    with pytest.raises(SourceError, match=message):
        track = load_labels(tmp_path / "m", n_frames=3, size=(W, H))
        for k in range(3):
            track[k]


def test_masks_match_a_folder_footage_by_file_name(tmp_path):
    _masks(tmp_path / "m", 2)
    (tmp_path / "m" / "m0.png").rename(tmp_path / "m" / "frame_b.png")
    (tmp_path / "m" / "m1.png").rename(tmp_path / "m" / "frame_a.png")
    track = load_labels(tmp_path / "m", n_frames=2, size=(W, H), frame_names=["frame_b.png", "frame_a.png"])
    assert track[0].line_truth(False)[1].boxes()[0] == (4.0, 2.0, 9.0, 10.0)
    with pytest.raises(SourceError, match=r"no mask for footage frame 'frame_c'"):
        load_labels(tmp_path / "m", n_frames=2, size=(W, H), frame_names=["frame_b.png", "frame_c.png"])


def _coco(tmp_path: Path, anns: list[dict], images=None) -> Path:
    images = images or [{"id": 10 + k, "file_name": f"f{k}.png", "width": W, "height": H} for k in range(2)]
    p = tmp_path / "labels.json"
    p.write_text(json.dumps({"images": images, "annotations": anns,
                             "categories": [{"id": 1, "name": "person"}, {"id": 2, "name": "car"}]}))
    return p


def test_coco_boxes_with_track_ids(tmp_path):
    p = _coco(tmp_path, [
        {"id": 1, "image_id": 10, "category_id": 1, "bbox": [1, 2, 3, 4], "track_id": 7, "visible": 0.5},
        {"id": 2, "image_id": 11, "category_id": 2, "bbox": [2, 2, 3, 4], "track_id": 7},
        {"id": 3, "image_id": 11, "category_id": 1, "bbox": [5, 5, 1, 1], "object_id": 9},
    ])
    track = load_labels(p, n_frames=2, size=(W, H))
    assert track.kind == "boxes"
    assert track[0].ids.tolist() == [7] and track[0].boxes.tolist() == [[1, 2, 4, 6]]
    assert track[0].visible.tolist() == [0.5]
    assert track[1].ids.tolist() == [7, 9]
    assert track.class_of(9) == "person"


def test_coco_rle_and_polygons_decode_like_pycocotools(tmp_path):
    mask_util = pytest.importorskip("pycocotools.mask")
    rng = np.random.default_rng(0)
    m = np.zeros((H, W), np.uint8)
    m[3:15, 5:20] = 1
    m[rng.random((H, W)) < 0.1] = 1
    rle = mask_util.encode(np.asfortranarray(m))
    compressed = {"size": rle["size"], "counts": rle["counts"].decode()}
    np.testing.assert_array_equal(rle_decode(compressed, "x"), m.astype(bool))
    counts, value, run = [], 0, 0
    for v in m.flatten(order="F").tolist():  # uncompressed COCO RLE: alternating runs of 0s and 1s
        if v != value:
            counts.append(run)
            value, run = v, 0
        run += 1
    counts.append(run)
    np.testing.assert_array_equal(rle_decode({"size": [H, W], "counts": counts}, "x"), m.astype(bool))
    poly = [[4.0, 3.0, 20.0, 5.0, 15.0, 18.0, 6.0, 14.0]]
    p = _coco(tmp_path, [{"id": 1, "image_id": 10, "bbox": [4, 3, 16, 15], "track_id": 1, "segmentation": poly},
                         {"id": 2, "image_id": 11, "bbox": [0, 0, 1, 1], "track_id": 1,
                          "segmentation": compressed}])
    track = load_labels(p, n_frames=2, size=(W, H))
    ours = track[0].amodal[1]
    theirs = mask_util.decode(mask_util.frPyObjects(poly, H, W)).any(axis=2)
    # rollcam takes pixel centres inside the polygon; pycocotools traces an upsampled outline: a few % differ.
    assert np.sum(ours != theirs) <= 0.05 * theirs.sum()
    assert ours[10, 12] and not ours[20, 30]
    np.testing.assert_array_equal(track[1].amodal[1], m.astype(bool))


@pytest.mark.parametrize(("anns", "message"), [
    ([{"id": 1, "image_id": 99, "bbox": [0, 0, 1, 1], "track_id": 1}], r"annotation 0 \(id 1\): image_id 99 names no"),
    ([{"id": 1, "image_id": 10, "bbox": [0, 0, 1, 1]}], r"annotation 0 \(id 1\): needs a positive integer track id"),
    ([{"id": 1, "image_id": 10, "bbox": [0, 0, 1], "track_id": 1}], r"bbox must be \[x, y, w, h\]"),
    ([{"id": 1, "image_id": 10, "bbox": [0, 0, 1, 1], "track_id": 1},
      {"id": 2, "image_id": 10, "bbox": [0, 0, 1, 1], "track_id": 1}], r"track id 1 appears twice in image 10"),
    ([{"id": 1, "image_id": 10, "bbox": [0, 0, 1, 1], "track_id": 1, "segmentation": {"size": [H, W],
                                                                                     "counts": [5]}}],
     r"RLE counts sum to 5"),
])
def test_bad_coco_names_the_file_and_annotation(tmp_path, anns, message):
    p = _coco(tmp_path, anns)
    with pytest.raises(SourceError, match=message):
        load_labels(p, n_frames=2, size=(W, H))[0]


def test_malformed_or_mismatched_coco(tmp_path):
    p = tmp_path / "bad.json"
    p.write_text('{"images": [')
    with pytest.raises(SourceError, match=r"bad\.json'?: malformed JSON .* line 1"):
        load_labels(p, n_frames=2, size=(W, H))
    p = _coco(tmp_path, [], images=[{"id": 1, "file_name": "f0.png"}])
    with pytest.raises(SourceError, match=r"labels\.json'?: holds 1 images, the footage 2 frames"):
        load_labels(p, n_frames=2, size=(W, H))
    with pytest.raises(SourceError, match=r"no image for footage frame 'f1\.png'"):
        load_labels(p, n_frames=2, size=(W, H), frame_names=["f0.png", "f1.png"])


def test_mot_text(tmp_path):
    p = tmp_path / "gt.txt"
    p.write_text("1,4,10,5,6,12,1,1,0.75\n2,4,11,5,6,12,1,1,1.0\n2,5,0,0,3,3,1,3,1\n")
    assert detect_format(p) == "mot"
    track = load_labels(p, n_frames=3, size=(W, H))
    assert track[0].boxes.tolist() == [[10, 5, 16, 17]] and track[0].visible.tolist() == [0.75]
    assert track[1].ids.tolist() == [4, 5] and track.class_of(5) == "class3" and track.class_of(4) == "person"
    assert track[2].ids.tolist() == []


@pytest.mark.parametrize(("text", "message"), [
    ("1,4,10,5\n", r"gt\.txt'? line 1: need frame,id,x,y,w,h"),
    ("1,4,10,5,6,x\n", r"gt\.txt'? line 1: not numbers"),
    ("0,4,10,5,6,12\n", r"gt\.txt'? line 1: frame '0' is not in 1\.\.3"),
    ("\n9,4,10,5,6,12\n", r"gt\.txt'? line 2: frame '9' is not in 1\.\.3"),
    ("1,4,1,1,1,1\n1,4,2,2,2,2\n", r"line 2: id 4 appears twice in frame 1"),
])
def test_bad_mot_names_the_line(tmp_path, text, message):
    p = tmp_path / "gt.txt"
    p.write_text(text)
    with pytest.raises(SourceError, match=message):
        load_labels(p, n_frames=3, size=(W, H))


def test_yolo_per_frame_files_with_track_ids(tmp_path):
    d = tmp_path / "y"
    d.mkdir()
    (d / "f0.txt").write_text("0 0.5 0.5 0.25 0.5 3\n")
    (d / "f1.txt").write_text("0 0.5 0.5 0.25 0.5 0.9 3\n1 0.1 0.1 0.1 0.1 8\n")
    assert detect_format(d) == "yolo"
    track = load_labels(d, n_frames=2, size=(W, H))
    assert track[0].boxes.tolist() == [[12.0, 6.0, 20.0, 18.0]]
    assert track[1].ids.tolist() == [3, 8] and track.class_of(8) == "class1"
    (d / "f1.txt").write_text("0 0.5 0.5 0.25 0.5\n")
    with pytest.raises(SourceError, match=r"f1\.txt'? line 1: need 'class cx cy w h id'"):
        load_labels(d, n_frames=2, size=(W, H))[1]
    (d / "f1.txt").unlink()
    with pytest.raises(SourceError, match=r"holds 1 label files, the footage 2 frames"):
        load_labels(d, n_frames=2, size=(W, H))


# ------------------------------------------------------------------ hostile files (issue 37 F1-F5)
@pytest.mark.parametrize("case", ["png", "npy", "npy3d"])
def test_masks_declaring_a_huge_size_are_refused_from_the_header(tmp_path, case):
    """F2/F3: the size a PNG's IHDR or an .npy header declares is checked before anything is decoded."""
    _masks(tmp_path / "m", 2)
    (tmp_path / "m" / "m1.png").unlink()
    if case == "png":
        png_header_only(tmp_path / "m" / "m1.png", 30000, 30000)
    else:
        npy_header_only(tmp_path / "m" / "m1.npy", (100000, 100000) if case == "npy" else (100000, 100000, 4))
    with pytest.raises(SourceError, match=r"m1\.(png|npy)'?: mask is 100000x100000|m1\.png'?: mask is 30000x30000"
                       ) as info:
        load_labels(tmp_path / "m", n_frames=2, size=(W, H))[1]
    assert "from its header" in str(info.value) and "\n" not in str(info.value)


def test_a_coco_rle_declaring_a_huge_mask_is_refused_before_allocation(tmp_path):
    """F1: the RLE's declared size is the footage's, checked before its counts are decoded (main allocated the
    declared 60000x60000 mask, 3.6 GB, before comparing it with the footage)."""
    import tracemalloc

    rle = {"size": [60000, 60000], "counts": [0, 60000 * 60000]}
    p = _coco(tmp_path, [{"id": 5, "image_id": 10, "bbox": [0, 0, 1, 1], "track_id": 1, "segmentation": rle},
                         {"id": 6, "image_id": 11, "bbox": [0, 0, 1, 1], "track_id": 1, "segmentation": [[0, 0, 1, 0,
                                                                                                           1, 1]]}])
    tracemalloc.start()
    try:
        with pytest.raises(SourceError, match=r"labels\.json'? frame 0 track 1: RLE mask declares 60000x60000, "
                                              r"the footage is 32x24"):
            load_labels(p, n_frames=2, size=(W, H))[0]
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 50 * 2**20, peak
    with pytest.raises(SourceError, match=r"RLE mask declares 32x25"):
        rle_decode({"size": [25, 32], "counts": [800]}, "x", (W, H))


@pytest.mark.parametrize(("bbox", "message"), [
    ([float("nan"), 1, 5, 5], r"annotation 0 \(id 1\) bbox: box \[x, y, w, h\] must be finite numbers, got \[nan"),
    ([0, 0, float("inf"), 5], r"annotation 0 \(id 1\) bbox: box \[x, y, w, h\] must be finite numbers"),
    ([1e308, 0, 1e308, 1], r"annotation 0 \(id 1\) bbox: box \[1e\+308, 0, 1e\+308, 1\] reaches more than 100"),
    ([0, 0, -1, 5], r"annotation 0 \(id 1\) bbox: box width and height must be >= 0, got -1x5"),
    ([0, 0, True, 5], r"bbox must be \[x, y, w, h\]"),
])
def test_coco_boxes_must_be_finite_sized_and_near_the_footage(tmp_path, bbox, message):
    """F5: main accepted these silently (MOT already refused NaN)."""
    p = _coco(tmp_path, [{"id": 1, "image_id": 10, "bbox": bbox, "track_id": 1}])
    with pytest.raises(SourceError, match=message):
        load_labels(p, n_frames=2, size=(W, H))[0]


def test_coco_polygons_must_be_finite(tmp_path):
    p = _coco(tmp_path, [{"id": 1, "image_id": 10, "bbox": [0, 0, 1, 1], "track_id": 1,
                          "segmentation": [[0, 0, float("nan"), 0, 1, 1]]},
                         {"id": 2, "image_id": 11, "bbox": [0, 0, 1, 1], "track_id": 1,
                          "segmentation": [[0, 0, 1, 0, 1, 1]]}])
    with pytest.raises(SourceError, match=r"frame 0 track 1: polygon coordinates must be finite numbers"):
        load_labels(p, n_frames=2, size=(W, H))[0]


@pytest.mark.parametrize(("line", "message"), [
    ("nan 0.5 0.5 0.25 0.5 3", r"f0\.txt'? line 1: class and id must be integers"),
    ("0 0.5 0.5 0.25 0.5 nan", r"f0\.txt'? line 1: class and id must be integers"),
    ("inf 0.5 0.5 0.25 0.5 3", r"f0\.txt'? line 1: class and id must be integers"),
    ("0 0.5 0.5 0.25 0.5 inf", r"f0\.txt'? line 1: class and id must be integers"),
    ("0 nan 0.5 0.25 0.5 3", r"f0\.txt'? line 1: box \[x, y, w, h\] must be finite numbers"),
    ("0 0.5 0.5 -0.25 0.5 3", r"f0\.txt'? line 1: box width and height must be >= 0"),
    ("0 1e300 0.5 0.25 0.5 3", r"f0\.txt'? line 1: box .* reaches more than 100 frames"),
])
def test_yolo_non_finite_ids_classes_and_boxes_name_the_line(tmp_path, line, message):
    """F4: nan/inf ids and classes ended in a traceback on main (int(nan))."""
    d = tmp_path / "y"
    d.mkdir()
    (d / "f0.txt").write_text(line + "\n")
    (d / "f1.txt").write_text("")
    with pytest.raises(SourceError, match=message):
        load_labels(d, n_frames=2, size=(W, H))[0]


@pytest.mark.parametrize(("text", "message"), [
    ("1,4,1e308,0,1e308,1\n", r"gt\.txt'? line 1: box .* reaches more than 100 frames"),
    ("1,4,0,0,-2,1\n", r"gt\.txt'? line 1: box width and height must be >= 0, got -2x1"),
])
def test_mot_boxes_are_checked_as_coco_and_yolo_boxes_are(tmp_path, text, message):
    p = tmp_path / "gt.txt"
    p.write_text(text)
    with pytest.raises(SourceError, match=message):
        load_labels(p, n_frames=3, size=(W, H))
