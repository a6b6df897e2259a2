"""rollcam train --background: images with no person (flat frames, crops of person-free regions, empty streets)
joined to the training images, drawn from the run's seed alone, holding no box."""

from __future__ import annotations

import json

import numpy as np
import pytest
from rollcam.common.errors import ConfigError
from rollcam.host.cli import main

pytest.importorskip("torch", reason="rollcam train needs the 'train' extra (torch)")
pytest.importorskip("faster_coco_eval")

from rollcam.host.datasets import DatasetConfig, build_dataset
from rollcam.host.training.background import KINDS, MARGIN_PX, flat_frame, free_region
from rollcam.host.training.config import TrainConfig
from rollcam.host.training.data import FittedImages, load_split, make_batch, open_dataset

TINY = DatasetConfig(size=(192, 108), scenes=4, cameras=2, times=("noon", "dusk"), speeds=("normal",), frames=6,
                     pedestrians=10, seed=4)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    return build_dataset(TINY, tmp_path_factory.mktemp("bg") / "ds").out_dir


def _images(ds, fraction=1.0, seed=3):
    info = open_dataset(ds)
    sets = load_split(info, info.subsets, "train")
    return FittedImages(sets, 96, 56, "bgr").with_backgrounds(fraction, seed, info.card)


def test_backgrounds_follow_the_images_hold_no_box_and_are_the_same_for_a_seed(tiny):
    a, b = _images(tiny), _images(tiny)
    n = len(a.entries)
    assert len(a) == 2 * n and len(a.backgrounds) == n
    kinds = [a.backgrounds.kind(i) for i in range(len(a.backgrounds))]
    assert kinds[:3] == list(KINDS)
    for i in range(n, len(a)):
        img, boxes, ignore = a.get(i)
        assert img.shape == (56, 96, 3) and img.dtype == np.uint8
        assert boxes.shape == (0, 4) and ignore.shape == (0,)
        assert np.array_equal(img, b.get(i)[0])  # drawn from the seed and the index alone
    street = a.get(n + 2)[0]
    assert street.std() > 10  # a rendered street, not a flat frame
    other = _images(tiny, seed=4).get(n)[0]
    assert not np.array_equal(other, a.get(n)[0])
    batch = make_batch(a, np.arange(n, len(a)), np.random.default_rng(0))
    assert batch["image"].shape[0] == n and float(batch["heat"].max()) == 0.0  # no person anywhere in them


def test_a_fraction_sets_how_many_and_zero_adds_none(tiny):
    n = len(_images(tiny, 0.0).entries)
    assert len(_images(tiny, 0.0)) == n and _images(tiny, 0.0).backgrounds is None
    assert len(_images(tiny, 0.5)) == n + round(0.5 * n)


def test_crops_keep_clear_of_every_box_and_a_crowded_picture_gives_none():
    rng = np.random.default_rng(0)
    content = (0.0, 0.0, 640.0, 360.0)
    boxes = np.array([[200, 150, 240, 260], [400, 120, 430, 200]], np.float32)
    for _ in range(50):
        x0, _y0, x1, y1 = free_region(boxes, content, rng)
        clear_above = y1 <= boxes[:, 1].min() - MARGIN_PX
        clear_left = x1 <= boxes[:, 0].min() - MARGIN_PX
        clear_right = x0 >= boxes[:, 2].max() + MARGIN_PX
        assert clear_above or clear_left or clear_right
    assert free_region(np.zeros((0, 4), np.float32), content, rng) == content
    crowded = np.array([[0, 5, 640, 360]], np.float32)
    assert free_region(crowded, content, rng) is None


def test_flat_frames_span_black_to_white():
    levels = [flat_frame(np.random.default_rng(k), 64, 36).mean() for k in range(200)]
    assert min(levels) < 20 and max(levels) > 235
    f = flat_frame(np.random.default_rng(1), 64, 36)
    assert f.std() < 15  # featureless: a level, a gentle ramp and noise


def test_training_with_backgrounds_end_to_end_and_its_card_rebuilds_it(tiny, tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["train", str(tiny), "--model", "pico", "--epochs", "1", "--imgsz", "96x56", "--batch", "4",
                 "--threads", "1", "--background", "0.5", "--out", str(out), "--json"])
    assert code == 0
    card = json.loads(capsys.readouterr().out)
    assert card["config"]["background"] == 0.5
    assert "--background 0.5" in card["command"]
    assert "0.5 background image(s) per training image" in (out / "README.md").read_text()


def test_bad_background_options_are_refused(tiny, tmp_path, capsys):
    assert main(["train", str(tiny), "--background", "1.5", "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "--background" in err and err.count("\n") == 1
    with pytest.raises(ConfigError, match="raw-mosaic model"):
        TrainConfig(dataset="d", input="raw", background=0.1)
    assert TrainConfig.added_keys()["background"] == 0.0 == TrainConfig(dataset="d").background
