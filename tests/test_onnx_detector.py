"""``onnx:`` detectors on tiny models the tests build with onnx.helper, one per output layout."""

from __future__ import annotations

import numpy as np
import pytest
from rollcam.common.errors import ConfigError, MissingDependencyError
from rollcam.host.detectors import load_detector
from rollcam.host.detectors.ops import iou_matrix, letterbox, nms, suppress_contained, tile_windows

onnx = pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")
from onnx import TensorProto, helper  # noqa: E402


def _constant_model(path, inp, outputs, input_dtype=TensorProto.FLOAT):
    """A model whose outputs are fixed tensors plus 0 * mean(input), so the input is really read."""
    nodes = [helper.make_node("Cast", ["images"], ["x"], to=TensorProto.FLOAT),
             helper.make_node("ReduceMean", ["x"], ["m"], keepdims=0),
             helper.make_node("Constant", [], ["zero"], value=helper.make_tensor("z", TensorProto.FLOAT, [], [0.0])),
             helper.make_node("Mul", ["m", "zero"], ["m0"])]
    outs = []
    for name, value in outputs.items():
        value = np.asarray(value, np.float32)
        nodes.append(helper.make_node("Constant", [], [name + "_c"], value=helper.make_tensor(
            name + "_t", TensorProto.FLOAT, value.shape, value.ravel().tolist())))
        nodes.append(helper.make_node("Add", [name + "_c", "m0"], [name]))
        outs.append(helper.make_tensor_value_info(name, TensorProto.FLOAT, list(value.shape)))
    graph = helper.make_graph(nodes, "tiny", [helper.make_tensor_value_info("images", input_dtype, inp)], outs)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return str(path)


@pytest.fixture
def yolo_model(tmp_path):
    # [1, 4 + 2 classes, 4 candidates] in 64x64 input pixels: cx, cy, w, h, score(class 0), score(class 1)
    cand = np.array([
        [32, 32, 16, 32, 0.10, 0.90],   # class 1, kept
        [33, 32, 16, 32, 0.05, 0.80],   # duplicate of the first: NMS drops it
        [10, 40, 8, 8, 0.70, 0.00],     # class 0, kept
        [50, 20, 8, 8, 0.10, 0.20],     # below conf
    ] + [[0, 0, 1, 1, 0, 0]] * 6, np.float32)  # N > 4 + C, as in real exports (8400 candidates)
    return _constant_model(tmp_path / "yolo.onnx", [1, 3, 64, 64], {"output0": cand.T[None]})


def test_yolo_layout_letterbox_nms_and_class_filter(yolo_model):
    det = load_detector(f"onnx:{yolo_model}?conf=0.5")
    assert det.layout == "yolo" and (det.width, det.height) == (64, 64) and det.letterbox
    image = np.zeros((64, 128, 3), np.uint8)  # letterboxed: scale 0.5, 16 px bars above and below
    d = det.detect(image)
    assert d.classes.tolist() == [1, 0]
    assert d.scores.tolist() == pytest.approx([0.9, 0.7])
    # net box (24, 16, 40, 48) -> source ((24-0)/0.5, (16-16)/0.5, ...) = (48, 0, 80, 64)
    np.testing.assert_allclose(d.boxes[0], [48, 0, 80, 64], atol=1e-4)
    np.testing.assert_allclose(d.boxes[1], [12, 40, 28, 56], atol=1e-4)
    only0 = load_detector(f"onnx:{yolo_model}?conf=0.5&classes=0").detect(image)
    assert only0.classes.tolist() == [0]
    assert len(load_detector(f"onnx:{yolo_model}?conf=0.5&iou=0.99").detect(image)) == 3


def test_yolo_transposed_output(tmp_path):
    cand = np.array([[32, 32, 16, 32, 0.9]] + [[0, 0, 1, 1, 0.0]] * 9, np.float32)  # [1, N=10, 5]
    path = _constant_model(tmp_path / "t.onnx", [1, 3, 64, 64], {"output0": cand[None]})
    d = load_detector(f"onnx:{path}").detect(np.zeros((64, 64, 3), np.uint8))
    assert len(d) == 1
    np.testing.assert_allclose(d.boxes[0], [24, 16, 40, 48], atol=1e-4)


@pytest.fixture
def ssd_model(tmp_path):
    boxes = np.array([[[0.25, 0.5, 0.75, 1.0], [0.0, 0.0, 0.5, 0.25], [0.1, 0.1, 0.2, 0.2], [0, 0, 0, 0]]])
    return _constant_model(tmp_path / "ssd.onnx", [1, 32, 32, 3], {
        "detection_boxes": boxes, "detection_scores": [[0.95, 0.6, 0.1, 0.9]],
        "detection_classes": [[1, 3, 1, 1]], "num_detections": [3]}, input_dtype=TensorProto.UINT8)


def test_ssd_layout_normalised_yxyx_and_class_offset(ssd_model):
    det = load_detector(f"onnx:{ssd_model}?conf=0.5&class_offset=1")
    assert det.layout == "ssd" and not det.letterbox and det._uint8
    d = det.detect(np.zeros((100, 200, 3), np.uint8))
    assert d.classes.tolist() == [0, 2]  # the 4th box lies past num_detections
    np.testing.assert_allclose(d.boxes[0], [100, 25, 200, 75], atol=1e-3)
    np.testing.assert_allclose(d.boxes[1], [0, 0, 50, 50], atol=1e-3)
    persons = load_detector(f"onnx:{ssd_model}?conf=0.5&class_offset=1&classes=0").detect(
        np.zeros((100, 200, 3), np.uint8))
    assert persons.classes.tolist() == [0]


def test_tiling_finds_boxes_in_each_tile_and_merges(yolo_model):
    det = load_detector(f"onnx:{yolo_model}?conf=0.5&tiles=2x1&overlap=0&full=0&classes=1")
    d = det.detect(np.zeros((64, 256, 3), np.uint8))
    # each 128x64 tile has the class-1 box at (48, 0, 80, 64) in tile pixels
    np.testing.assert_allclose(np.sort(d.boxes[:, 0]), [48, 176], atol=1e-3)


def test_a_piece_inside_a_better_box_is_suppressed_before_nms():
    """A person cut by a tile border: the piece (IoU 0.56 with the whole, so NMS at 0.45 would not remove it, but
    lying wholly inside it) goes when the whole scores higher; scoring higher itself it removes the whole
    (the measure is symmetric: the smaller's area); another class, or a box less than half inside, stays."""
    whole, piece = [100, 10, 140, 110], [100, 10, 140, 66]
    assert iou_matrix([whole], [piece])[0, 0] > 0.45
    boxes = np.array([whole, piece, [130, 60, 170, 110], [60, 10, 90, 40]], np.float32)
    keep = suppress_contained(boxes, np.array([0.9, 0.6, 0.5, 0.4]), np.array([0, 0, 0, 0]))
    assert keep.tolist() == [0, 2, 3]  # the third lies 25 % inside the whole: a neighbour, kept
    assert suppress_contained(boxes, np.array([0.5, 0.9, 0.4, 0.3]), np.zeros(4, int)).tolist() == [1, 2, 3]
    assert suppress_contained(boxes, np.array([0.9, 0.6, 0.5, 0.4]), np.array([0, 1, 0, 0])).tolist() == [0, 1, 2, 3]
    assert suppress_contained(np.zeros((0, 4)), np.zeros(0), np.zeros(0, int)).tolist() == []


def test_bad_onnx_specs(tmp_path, yolo_model):
    with pytest.raises(ConfigError, match="does not exist"):
        load_detector(f"onnx:{tmp_path / 'none.onnx'}")
    with pytest.raises(ConfigError, match="name a model"):
        load_detector("onnx:")
    with pytest.raises(ConfigError, match="conf"):
        load_detector(f"onnx:{yolo_model}?conf=2")
    with pytest.raises(ConfigError, match="fixed"):
        load_detector(f"onnx:{yolo_model}?size=32x32")
    (tmp_path / "junk.onnx").write_bytes(b"not a model")
    with pytest.raises(ConfigError, match="cannot be loaded"):
        load_detector(f"onnx:{tmp_path / 'junk.onnx'}")


def test_ops():
    img, place = letterbox(np.zeros((50, 100, 3), np.uint8), 64, 64)
    assert img.shape == (64, 64, 3) and place.pad_y == 16 and place.scale_x == pytest.approx(0.64)
    assert iou_matrix([[0, 0, 2, 2]], [[1, 0, 3, 2], [5, 5, 6, 6]]).tolist() == [[pytest.approx(1 / 3), 0.0]]
    keep = nms(np.array([[0, 0, 10, 10], [1, 0, 11, 10], [1, 0, 11, 10]]), np.array([0.5, 0.9, 0.8]),
               np.array([0, 0, 1]), 0.5)
    assert keep.tolist() == [1, 2]
    wins = list(tile_windows(100, 50, 2, 1, 0.2))
    assert wins[0][0] == 0 and wins[-1][2] == 100 and wins[0][2] > wins[1][0]


def _nms_by_definition(boxes, scores, classes, threshold, max_det):
    """Greedy NMS spelled out: best first, keep a box unless a kept box of its class overlaps it too much."""
    kept: list[int] = []
    for i in sorted(range(len(boxes)), key=lambda i: -scores[i]):  # sorted() is stable: ties in input order
        if len(kept) == max_det:
            break
        if all(classes[k] != classes[i] or iou_matrix([boxes[k]], [boxes[i]])[0, 0] <= threshold for k in kept):
            kept.append(i)
    return kept


def test_nms_keeps_what_greedy_suppression_keeps_by_definition():
    rng = np.random.default_rng(7)
    for _ in range(300):
        n = int(rng.integers(0, 60))
        xy = rng.uniform(-20, 200, (n, 2))
        boxes = np.concatenate([xy, xy + rng.uniform(0, 60, (n, 2))], axis=1).astype(np.float32)
        scores = np.round(rng.uniform(0, 1, n), 1)  # coarse scores: many ties
        classes = rng.integers(0, 3, n)
        threshold, max_det = float(rng.choice([0.0, 0.3, 0.45, 0.7])), int(rng.integers(1, 40))
        keep = nms(boxes, scores, classes, threshold, max_det)
        assert keep.dtype == np.int64
        assert keep.tolist() == _nms_by_definition(boxes, scores, classes, threshold, max_det)
    assert nms(np.zeros((0, 4)), np.zeros(0), np.zeros(0), 0.5).tolist() == []
    assert nms(np.array([[0, 0, 1, 1]]), np.array([1.0]), np.array([0]), 0.5, max_det=0).tolist() == []


def test_ssdlite_is_packaged_and_finds_a_rendered_pedestrian():
    from rollcam.host import open_camera
    from rollcam.host.detectors.ops import iou_matrix

    det = load_detector("ssdlite")
    assert det.name == "ssdlite" and det.class_names == {0: "person"} and (det.width, det.height) == (300, 300)
    assert len(det.detect(np.full((300, 300, 3), 200, np.uint8))) == 0
    with open_camera("emu:letsroll?seed=2&pedestrians=30&camera=1&shutter=global&frames=1") as cam:
        frame = cam.read()
    d = det.detect(frame.data)
    truth = [o.box_gs for o in frame.objects if o.box_gs is not None]
    assert len(d) >= 1 and (d.classes == 0).all()
    assert iou_matrix(d.boxes, truth).max(axis=1).max() > 0.5
    with pytest.raises(ConfigError, match="fixed by the ssdlite model"):
        load_detector("ssdlite?layout=yolo")


def test_raw_input_model_gets_the_mosaic(tmp_path):
    cand = np.array([[16, 16, 8, 8, 0.9]] + [[0, 0, 1, 1, 0.0]] * 9, np.float32)
    path = _constant_model(tmp_path / "raw.onnx", [1, 1, 32, 32], {"output0": cand.T[None]})
    det = load_detector(f"onnx:{path}?input=raw&letterbox=0")
    assert det.input == "raw"
    tensor, _ = det._prepare(np.full((64, 64), 1023, np.uint16))
    assert tensor.shape == (1, 1, 32, 32) and tensor.max() == pytest.approx(1023 / 65535)
    ten_bit = load_detector(f"onnx:{path}?input=raw&letterbox=0&bits=10")
    assert ten_bit._prepare(np.full((64, 64), 1023, np.uint16))[0].max() == pytest.approx(1.0)
    d = det.detect(np.zeros((64, 64), np.uint16))
    np.testing.assert_allclose(d.boxes[0], [24, 24, 40, 40], atol=1e-4)


def test_missing_runtimes_name_the_install(monkeypatch, yolo_model):
    import onnxruntime

    if "CUDAExecutionProvider" not in onnxruntime.get_available_providers():
        with pytest.raises(MissingDependencyError, match="onnxruntime-gpu"):
            load_detector(f"onnx:{yolo_model}?device=cuda")
    monkeypatch.setitem(__import__("sys").modules, "onnxruntime", None)
    with pytest.raises(MissingDependencyError, match=r"needs onnxruntime, an install dependency of rollcam missing "
                                                     r"from this broken install \(pip install onnxruntime\)$"):
        load_detector("ssdlite")


def _failing_model(path) -> str:
    """A model that loads (its input size is dynamic) but fails at run time: it reshapes its input to 6 x 1000."""
    shape = helper.make_tensor("s", TensorProto.INT64, [3], [1, 6, 1000])
    graph = helper.make_graph(
        [helper.make_node("Constant", [], ["shape"], value=shape), helper.make_node("Reshape", ["images", "shape"],
                                                                                     ["output0"])],
        "fails", [helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, "h", "w"])],
        [helper.make_tensor_value_info("output0", TensorProto.FLOAT, [1, 6, 1000])])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.save(model, str(path))
    return str(path)


def test_a_model_that_loads_but_fails_at_run_time_is_one_clear_error(tmp_path, capsys):
    """Issue 37 O2: onnxruntime's own error came out as a traceback on main."""
    from rollcam.host.cli import main

    det = load_detector(f"onnx:{_failing_model(tmp_path / 'bad.onnx')}?size=64x64")
    with pytest.raises(ConfigError, match=r"bad\.onnx'? failed on a \[1, 3, 64, 64\] float32 input: .*Reshape"):
        det.detect(np.zeros((64, 64, 3), np.uint8))
    code = main(["detect", "emu:imx219?scene=flat&size=64x64", "--frames", "1", "--out", str(tmp_path / "out"),
                 "--detector", f"onnx:{tmp_path / 'bad.onnx'}?size=64x64"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("rollcam: error: ") and "bad.onnx" in err[0], err


def test_a_raw_model_given_a_colour_picture_says_so(tmp_path):
    """Issue 37 O2: personnet-raw on an RGB dataset ended in onnxruntime's INVALID_ARGUMENT traceback on main."""
    det = load_detector("personnet-raw")
    with pytest.raises(ConfigError, match=r"raw-input model \(input=raw\) takes the sensor's one-channel mosaic, not a "
                                          r"320x180 picture of 3 channels"):
        det.detect(np.zeros((180, 320, 3), np.uint8))
