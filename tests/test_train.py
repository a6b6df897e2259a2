"""rollcam train: a tiny run end to end (train, export, evaluate through onnx:), resume, determinism, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
from rollcam.common.errors import ConfigError
from rollcam.host.cli import main

torch = pytest.importorskip("torch", reason="rollcam train needs the 'train' extra (torch)")
pytest.importorskip("onnx")
pytest.importorskip("faster_coco_eval")

from rollcam.host.datasets import DatasetConfig, build_dataset  # noqa: E402
from rollcam.host.training.config import TrainConfig  # noqa: E402
from rollcam.host.training.loss import build_targets  # noqa: E402
from rollcam.host.training.trainer import train  # noqa: E402

TINY = DatasetConfig(size=(192, 108), scenes=5, cameras=2, times=("noon",), speeds=("normal",), frames=6,
                     pedestrians=10, seed=4)


@pytest.fixture(scope="module")
def tiny_dataset(tmp_path_factory):
    return build_dataset(TINY, tmp_path_factory.mktemp("train") / "ds").out_dir


def _cfg(ds, **kw):
    base = {"dataset": str(ds), "model": "pico", "epochs": 2, "imgsz": (96, 56), "batch": 2, "threads": 1,
            "steps": 2, "seed": 3}
    return TrainConfig(**(base | kw))


class Stop(KeyboardInterrupt):
    """An interruption the tests raise after an epoch's checkpoint."""


def stop_after_first(epoch):
    """``on_epoch`` that interrupts a run once its first epoch is saved."""
    if epoch == 1:
        raise Stop


def _weights(run_dir):
    state = torch.load(str(run_dir / "last.pt"), map_location="cpu", weights_only=True)
    return {k: v.clone() for k, v in state["model"].items()}


def test_train_exports_onnx_that_eval_reads(tiny_dataset, tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["train", str(tiny_dataset), "--subset", "normal_rs", "--model", "pico", "--epochs", "2",
                 "--imgsz", "96x56", "--batch", "2", "--threads", "1", "--out", str(out), "--json"])
    assert code == 0
    card = json.loads(capsys.readouterr().out)
    for name in ("model.onnx", "last.pt", "train.json", "README.md", "curves.png"):
        assert (out / name).is_file(), name
    assert not (out / ".val.onnx").exists()
    assert card["subsets"] == ["normal_rs"] and card["val_subsets"] == ["normal_rs"]
    assert card["config"]["seed"] == 0 and len(card["history"]) == 2
    assert set(card["final"]) == {"P", "R", "mAP50", "mAP50_95"}
    assert "rollcam train" in card["command"] and card["git"].keys() == {"commit", "dirty"}
    assert (out / "curves.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    from rollcam.host.detectors import load_detector

    det = load_detector(f"onnx:{out / 'model.onnx'}?conf=0.01")
    assert (det.width, det.height, det.layout, det.input) == (96, 56, "yolo", "bgr")
    assert det.class_names == {0: "person"}
    assert len(det.detect(np.full((108, 192, 3), 90, np.uint8)).boxes.shape) == 2
    det.close()
    code = main(["eval", str(tiny_dataset), "--detector", f"onnx:{out / 'model.onnx'}?conf=0.01", "--split", "test",
                 "--json", "--out", str(tmp_path / "eval")])
    assert code == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc["results"]["normal"]) >= {"gs", "rs", "gs_to_rs"}
    assert 0.0 <= doc["results"]["normal"]["rs"]["mAP50"] <= 1.0


def test_same_seed_same_weights_and_resume_matches_an_uninterrupted_run(tiny_dataset, tmp_path):
    a = train(_cfg(tiny_dataset), tmp_path / "a")
    b = train(_cfg(tiny_dataset), tmp_path / "b")
    wa, wb = _weights(tmp_path / "a"), _weights(tmp_path / "b")
    assert all(torch.equal(wa[k], wb[k]) for k in wa)
    assert a.history[-1]["loss"] == b.history[-1]["loss"]

    with pytest.raises(Stop):
        train(_cfg(tiny_dataset), tmp_path / "c", on_epoch=stop_after_first)
    assert not (tmp_path / "c" / "model.onnx").exists()
    c = train(_cfg(tiny_dataset), tmp_path / "c")
    assert c.resumed_after == 1
    wc = _weights(tmp_path / "c")
    assert all(torch.equal(wa[k], wc[k]) for k in wa)
    assert [h["loss"] for h in c.history] == [h["loss"] for h in a.history]

    d = train(_cfg(tiny_dataset, seed=4), tmp_path / "d")
    assert not all(torch.equal(wa[k], _weights(tmp_path / "d")[k]) for k in wa)
    assert d.history[0]["loss"] != a.history[0]["loss"]


def test_resume_with_other_options_is_refused_and_init_loads_weights(tiny_dataset, tmp_path):
    train(_cfg(tiny_dataset, epochs=1), tmp_path / "a")
    with pytest.raises(ConfigError, match=r"differing: \['lr'\]"):
        train(_cfg(tiny_dataset, epochs=1, lr=1e-3), tmp_path / "a")
    fine = train(_cfg(tiny_dataset, epochs=1, init=str(tmp_path / "a" / "last.pt"), lr=1e-9), tmp_path / "b")
    assert fine.card["config"]["init"].endswith("last.pt")
    with pytest.raises(ConfigError, match="does not fit"):
        train(_cfg(tiny_dataset, epochs=1, model="nano", init=str(tmp_path / "a" / "last.pt")), tmp_path / "c")


def test_init_from_an_exported_onnx_reproduces_it_and_fine_tunes(tiny_dataset, tmp_path):
    ort = pytest.importorskip("onnxruntime")
    from rollcam.host.training.export import load_onnx_weights
    from rollcam.host.training.model import Exported, PersonNet, model_size

    train(_cfg(tiny_dataset, epochs=1), tmp_path / "a")
    onnx_path = tmp_path / "a" / "model.onnx"
    torch.manual_seed(11)
    net = PersonNet(model_size("pico"))
    rng = np.random.default_rng(0)
    calib = [torch.from_numpy(rng.random((2, 3, 56, 96), dtype=np.float32)) for _ in range(2)]
    load_onnx_weights(net, onnx_path, calib)
    x = rng.random((1, 3, 56, 96), dtype=np.float32)
    with torch.no_grad():
        ours = Exported(net.eval())(torch.from_numpy(x)).numpy()
    sess = ort.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"])
    theirs = sess.run(None, {"images": x})[0]
    assert np.allclose(ours, theirs, rtol=1e-4, atol=1e-4 * float(np.abs(theirs).max()))
    # the BatchNorms carry the calibration batches' statistics, not the identity the folding leaves
    bn = next(m for m in net.modules() if isinstance(m, torch.nn.BatchNorm2d))
    assert not torch.allclose(bn.running_var, torch.ones_like(bn.running_var), atol=1e-3)

    fine = train(_cfg(tiny_dataset, epochs=1, init=str(onnx_path)), tmp_path / "b")
    assert fine.card["config"]["init"].endswith("model.onnx") and (tmp_path / "b" / "model.onnx").is_file()
    with pytest.raises(ConfigError, match="does not fit"):
        train(_cfg(tiny_dataset, epochs=1, model="nano", init=str(onnx_path)), tmp_path / "c")
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"\x08\x07not a protobuf at all" * 3)
    with pytest.raises(ConfigError, match="is not an ONNX model"):
        train(_cfg(tiny_dataset, epochs=1, init=str(bad)), tmp_path / "d")
    assert not (tmp_path / "d" / "model.onnx").exists()


def test_weight_average_is_exported_resumes_exactly_and_old_checkpoints_still_resume(tiny_dataset, tmp_path):
    from rollcam.host.training.model import Exported, PersonNet, count_parameters, model_size
    from rollcam.host.training.trainer import WeightAverage

    # the average itself: the ramp, then the decay
    net = torch.nn.Linear(2, 1, bias=False)
    torch.nn.init.zeros_(net.weight)
    avg = WeightAverage(net, 0.5)
    with torch.no_grad():
        net.weight.fill_(1.0)
    avg.update(net)  # ramp: min(0.5, 2 / 11) = 2/11 of the old (0) and 9/11 of the new (1)
    assert torch.allclose(avg.net.weight, torch.full((1, 2), 9 / 11))
    for _ in range(40):
        avg.update(net)
    assert torch.allclose(avg.net.weight, torch.ones(1, 2), atol=1e-6)
    assert not avg.net.weight.requires_grad

    a = train(_cfg(tiny_dataset, ema=0.9), tmp_path / "a")
    state = torch.load(str(tmp_path / "a" / "last.pt"), map_location="cpu", weights_only=True)
    assert state["ema"]["updates"] == 4 and a.card["config"]["ema"] == 0.9 and "--ema 0.9" in a.card["command"]
    assert a.card["model"]["parameters"] == count_parameters(PersonNet(model_size("pico"))) > 0  # the size, averaged
    raw, averaged = state["model"], state["ema"]["weights"]
    assert any(not torch.equal(raw[k], averaged[k]) for k in raw if raw[k].dtype.is_floating_point)
    # model.onnx is the average: onnxruntime's output is the averaged network's, not the raw weights'
    ort = pytest.importorskip("onnxruntime")
    x = np.random.default_rng(0).random((1, 3, 56, 96), dtype=np.float32)
    theirs = ort.InferenceSession(str(tmp_path / "a" / "model.onnx"),
                                  providers=["CPUExecutionProvider"]).run(None, {"images": x})[0]

    def output(weights):
        net = PersonNet(model_size("pico"))
        net.load_state_dict(weights)
        with torch.no_grad():
            return Exported(net.eval())(torch.from_numpy(x)).numpy()

    # the box channels (the score channel's peak pick may flip on near ties of an untrained heatmap)
    assert np.allclose(output(averaged)[:, :4], theirs[:, :4], rtol=1e-4, atol=1e-3)
    assert not np.allclose(output(raw)[:, :4], theirs[:, :4], rtol=1e-4, atol=1e-3)

    with pytest.raises(Stop):
        train(_cfg(tiny_dataset, ema=0.9), tmp_path / "b", on_epoch=stop_after_first)
    train(_cfg(tiny_dataset, ema=0.9), tmp_path / "b")
    resumed = torch.load(str(tmp_path / "b" / "last.pt"), map_location="cpu", weights_only=True)
    assert resumed["ema"]["updates"] == 4
    assert all(torch.equal(averaged[k], resumed["ema"]["weights"][k]) for k in averaged)

    # a checkpoint written before --ema existed (no "ema" in its config) resumes as a run without it
    with pytest.raises(Stop):
        train(_cfg(tiny_dataset), tmp_path / "c", on_epoch=stop_after_first)
    old = torch.load(str(tmp_path / "c" / "last.pt"), map_location="cpu", weights_only=True)
    del old["config"]["ema"]
    torch.save(old, str(tmp_path / "c" / "last.pt"))
    with pytest.raises(ConfigError, match=r"differing: \['ema'\]"):
        train(_cfg(tiny_dataset, ema=0.9), tmp_path / "c")
    assert train(_cfg(tiny_dataset), tmp_path / "c").resumed_after == 1


@pytest.mark.parametrize(("argv", "message"), [
    (["--model", "huge"], "--model 'huge' is not one of"),
    (["--subset", "fast_rs"], "--subset 'fast_rs' is not a subset"),
    (["--val", "nope"], "--val 'nope' is not a subset"),
    (["--imgsz", "30x30"], "multiples of 4"),
    (["--epochs", "0"], "--epochs"),
    (["--input", "raw"], "--input raw needs a dataset of raw mosaics"),
    (["--init", "/nonexistent.pt"], "does not exist"),
    (["--ema", "1"], "--ema must be in [0, 1)"),
    (["--ema", "-0.5"], "--ema"),
])
def test_bad_arguments_exit_2_with_one_clear_line(tiny_dataset, tmp_path, capsys, argv, message):
    code = main(["train", str(tiny_dataset), *argv, "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert code == 2
    assert message in err and err.count("\n") == 1 and err.startswith("rollcam: error:")


def test_not_a_dataset_exits_2(tmp_path, capsys):
    assert main(["train", str(tmp_path), "--out", str(tmp_path / "run")]) == 2
    assert "is not a rollcam dataset folder" in capsys.readouterr().err


def test_targets_put_a_peak_on_each_box_centre_and_mask_ignore_regions():
    boxes = np.array([[8, 8, 24, 56], [60, 4, 64, 12]], np.float32)
    t = build_targets(boxes, np.array([False, True]), 16, 20)
    assert t["heat"].shape == (1, 16, 20) and t["n_pos"] == 1
    assert t["heat"][0, 8, 4] == 1.0  # centre (16, 32) / stride 4
    assert t["mask"][0, 1, 15] == 0.0 and t["mask"][0, 8, 4] == 1.0  # the ignore region's cells carry no loss
    assert np.isclose(t["weight"].sum(), np.log(16 * 48), rtol=1e-4)
    assert (t["reg"][:, 8, 4] == boxes[0]).all()
