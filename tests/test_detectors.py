"""The detector protocol: spec parsing, errors naming the problem, and HOG through ``load_detector``."""

from __future__ import annotations

import numpy as np
import pytest
from rollcam.common.errors import ConfigError
from rollcam.host.detectors import PERSON, Detections, Detector, load_detector, parse_spec


def test_parse_spec_splits_name_target_options():
    s = parse_spec("onnx:models/y.onnx?conf=0.3&classes=0")
    assert (s.name, s.target, s.options) == ("onnx", "models/y.onnx", {"conf": "0.3", "classes": "0"})


@pytest.mark.parametrize("spec, words", [("", "empty"), ("nope", "unknown detector 'nope'"),
                                         ("hog?scale=1", "scale"), ("hog?stride=-2", "stride"),
                                         ("hog?bogus=1", "bogus"), ("hog?scale=1.1&scale=1.2", "twice"),
                                         ("hog:file", "no target")])
def test_bad_specs_name_the_problem(spec, words):
    with pytest.raises(ConfigError, match=words):
        load_detector(spec)


def test_detections_validate_and_sort():
    d = Detections([[0, 0, 1, 1], [1, 1, 3, 3]], [0.2, 0.9], [0, 0]).sorted()
    assert d.scores.tolist() == pytest.approx([0.9, 0.2])
    assert d.to_json()[0]["box"] == [1.0, 1.0, 3.0, 3.0]
    with pytest.raises(ValueError, match="2 boxes, 1 scores"):
        Detections([[0, 0, 1, 1], [0, 0, 1, 1]], [0.1], [0, 0])


def test_hog_finds_a_rendered_walker():
    from rollcam.sim.render.renderer import Renderer
    from rollcam.sim.scenegen import make_street_scene

    det = load_detector("hog")
    assert isinstance(det, Detector) and det.input == "bgr" and det.class_names[PERSON] == "person"
    assert len(det.detect(np.zeros((256, 128, 3), np.uint8))) == 0
    scene = make_street_scene(2, n_pedestrians=30, width=960, height=540)
    found = 0
    for cam in range(len(scene.cameras)):
        r = Renderer(scene, cam)
        res = r.render_lines(np.full(540, 1_000_000_000, np.int64))
        dets = load_detector("hog?upscale=2&stride=8").detect(res.image)
        boxes = [b for b in res.truth.boxes() if b is not None and b[3] - b[1] > 70]
        for b in boxes:
            for db in dets.boxes:
                iw = min(b[2], db[2]) - max(b[0], db[0])
                ih = min(b[3], db[3]) - max(b[1], db[1])
                if iw > 0 and ih > 0 and iw * ih > 0.3 * (b[2] - b[0]) * (b[3] - b[1]):
                    found += 1
                    break
        if found:
            break
    assert found >= 1


@pytest.mark.parametrize("shape", [(54, 96, 3), (95, 64, 3), (200, 31, 3), (8, 8, 3)])
def test_hog_on_images_smaller_than_its_window_finds_nothing(shape):
    # OpenCV's detectMultiScale kills the process (SIGSEGV) when no window fits; the detector must not call it.
    assert len(load_detector("hog").detect(np.zeros(shape, np.uint8))) == 0
