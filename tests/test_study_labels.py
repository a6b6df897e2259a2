"""The study's label arm: the annotator model, relabelled sets, the plan and the report's answers (fast)."""

from __future__ import annotations

import numpy as np
import pytest
from rollcam.common.errors import ConfigError
from rollcam.host.cli import main
from rollcam.host.detectors.ops import iou_matrix
from rollcam.host.evaluation.loaders import EvalSet, ImageEntry
from rollcam.host.evaluation.metrics import Dets, Truth
from rollcam.host.training.config import TrainConfig
from rollcam.host.training.labels import ANNOTATOR, STUDY_BOX_AREA_PX2, box_stats, image_rng, relabel
from rollcam.host.training.study import bootstrap_se, plan_jobs
from rollcam.host.training.study_report import aggregate, label_statements
from rollcam.host.training.study_settings import MEDIUM, QUICK, REDUCED


def _boxes(n, rng):
    x0, y0 = rng.uniform(0, 500, n), rng.uniform(0, 300, n)
    w, h = rng.uniform(20, 80, n), rng.uniform(50, 160, n)
    return np.c_[x0, y0, x0 + w, y0 + h]


def test_annotator_agrees_with_itself_as_careful_people_do_and_shrinks_as_the_study_did():
    rng = np.random.default_rng(0)
    exact = _boxes(4000, rng)
    a, b = ANNOTATOR.draw(exact, rng), ANNOTATOR.draw(exact, rng)
    agreement = float(np.mean([iou_matrix(a[i:i + 1], b[i:i + 1])[0, 0] for i in range(len(a))]))
    assert agreement == pytest.approx(0.88, abs=0.01)
    area = lambda x: (x[:, 2] - x[:, 0]) * (x[:, 3] - x[:, 1])  # noqa: E731
    ratio = float(area(a).mean() / area(exact).mean())
    assert ratio == pytest.approx(STUDY_BOX_AREA_PX2["normal_rs"] / STUDY_BOX_AREA_PX2["normal_gs"], abs=0.01)
    # inside the exact box on average, clipped to the image when its size is given
    clipped = ANNOTATOR.draw(np.array([[-5.0, -5.0, 30.0, 60.0]]), rng, 20, 40)
    assert clipped.min() >= 0 and clipped[0, 2] <= 20 and clipped[0, 3] <= 40


def _set(name, shutter, truths):
    entries = [ImageEntry(f"{name}/images/test/{k}.png", None, i, t) for i, (k, t) in enumerate(truths.items())]
    return EvalSet(name, entries, ["person"], "fast", shutter)


def test_relabel_arms_take_the_gs_image_s_boxes_or_the_annotator_s_and_leave_gs_images_alone():
    gs_t = {"s000_noon_c0": Truth.of([[10, 10, 30, 70]], [0], None, 320, 180)}
    rs_t = {"s000_noon_c0": Truth.of([[12, 10, 36, 70]], [0], None, 320, 180)}
    sets = [_set("fast_gs", "gs", gs_t), _set("fast_rs", "rs", rs_t)]
    assert relabel(sets, "exact") == sets
    by = {s.name: s for s in relabel(sets, "gs")}
    assert by["fast_rs"].images[0].truth.boxes.tolist() == [[10, 10, 30, 70]]
    assert by["fast_gs"] is sets[0]
    hand = {s.name: s for s in relabel(sets, "hand")}["fast_rs"].images[0].truth.boxes
    again = {s.name: s for s in relabel(sets, "hand")}["fast_rs"].images[0].truth.boxes
    assert np.array_equal(hand, again)  # seeded by the image's name: the same labels in every run
    assert not np.array_equal(hand, rs_t["s000_noon_c0"].boxes)
    other = ANNOTATOR.draw(rs_t["s000_noon_c0"].boxes, image_rng(1, "s000_noon_c0.png"), 320, 180)
    assert not np.array_equal(hand, other)
    with pytest.raises(ConfigError, match="no GS image"):
        relabel([sets[1]], "gs")
    with pytest.raises(ConfigError, match="--labels 'sloppy'"):
        relabel(sets, "sloppy")
    stats = box_stats(sets[1])
    assert stats["boxes"] == 1 and stats["mean_area_px2"] == 24 * 60
    assert stats["mean_area_study_px2"] == pytest.approx(24 * 60 * 36)


def test_train_config_names_a_bad_label_arm_and_old_checkpoints_mean_exact_labels():
    with pytest.raises(ConfigError, match="--labels 'boxes'"):
        TrainConfig(dataset="d", labels="boxes")
    assert TrainConfig.added_keys()["labels"] == "exact" == TrainConfig(dataset="d").labels


def test_plan_has_the_label_arm_for_its_speeds_and_only_selects_it_with_its_baselines():
    for s in (QUICK, REDUCED, MEDIUM):
        jobs = plan_jobs(s)
        assert len({j.key for j in jobs}) == len(jobs)
        arms = {(j.speed, j.labels, j.seed) for j in jobs if j.group == "labels"}
        assert arms == {(sp, a, seed) for sp in s.label_speeds for a in ("gs", "hand") for seed in s.seeds}
    only = plan_jobs(REDUCED, ("labels",))
    assert {(j.speed, j.train[0][-2:], j.labels) for j in only} == {
        (sp, sh, arm) for sp in ("fast", "20") for sh, arm in (("gs", "exact"), ("rs", "exact"), ("rs", "gs"),
                                                             ("rs", "hand"))}
    for jobs in (only, plan_jobs(MEDIUM), plan_jobs(REDUCED)):  # seed-major: a study cut short has whole comparisons
        seeds = [j.seed for j in jobs]
        assert seeds == sorted(seeds)
    first = [j for j in plan_jobs(MEDIUM) if j.seed == MEDIUM.seeds[0]]
    assert {(j.speed, j.train[0][-2:], j.labels) for j in first} == {
        (sp, sh, arm) for sp in ("normal", "fast") for sh, arm in (("gs", "exact"), ("rs", "exact"), ("rs", "gs"),
                                                                 ("rs", "hand"))}
    with pytest.raises(ConfigError, match="--only 'nope'"):
        plan_jobs(REDUCED, ("nope",))


def test_every_setting_plans_datasets_its_scenes_can_hold():
    """medium first asked for more instants per split than its scenes x cameras x times hold."""
    from rollcam.host.datasets.plan import make_plan
    from rollcam.host.training.study import dataset_configs
    from rollcam.host.training.study_settings import SETTINGS

    for s in SETTINGS.values():
        for name, cfg in dataset_configs(s).items():
            assert make_plan(cfg), (s.name, name)


def test_study_only_names_a_bad_experiment_in_one_line_exit_2(tmp_path, capsys):
    assert main(["study", "--quick", "--only", "labels,t9", "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("rollcam: error:") and "'labels,t9'" in err[0]
    assert not (tmp_path / "s").exists()


def _cell(v):
    return {"P": v, "R": v, "mAP50": v, "mAP50_95": v / 2, "mAP50_95_se": 0.01}


def test_label_statements_say_which_arm_shows_the_study_s_pattern():
    results = []
    for seed, jitter in enumerate((0.0, 0.004, -0.004)):
        def add(key, group, train, test, seed=seed, **kw):
            job = {"key": f"{key}_s{seed}", "group": group, "speed": "fast", "train": [train], "seed": seed,
                   "raw": False, "scenes": None, "cameras": None} | kw
            results.append({"job": job, "test": test})
        add("fast_gs", "t1", "fast_gs", {"gs": _cell(0.80 + jitter), "rs": _cell(0.7), "gsrs": _cell(0.75)})
        add("fast_rs", "t1", "fast_rs", {"gs": _cell(0.7), "rs": _cell(0.80 - jitter), "gsrs": _cell(0.75)})
        # hand labels: mAP@0.5 the same, mAP@0.5:0.95 a quarter lower (the study's pattern)
        hand = {"gs": _cell(0.7), "rs": _cell(0.80 + jitter) | {"mAP50_95": 0.30 + jitter},
                "gsrs": _cell(0.75), "rs_exact": _cell(0.79)}
        add("fast_rs_handlabels", "labels", "fast_rs", hand, labels="hand")
    agg = aggregate(QUICK, results)
    text = label_statements(agg)
    exact = next(t for t in text if "exact RS labels" in t)
    hand = next(t for t in text if "hand-like labels" in t)
    assert "does not show the study's pattern" in exact
    assert "-25.0% (beyond the spread; with the test images' sampling, about 95 % interval" in hand
    assert hand.endswith("shows the study's pattern.")
    # the interval adds each group's test-image standard error (0.01) to the seed term
    d = agg["label_arm"]["fast"]["hand"]["gs_to_rs"]["mAP50_95"]
    gs = agg["label_arm"]["fast"]["gs_model"]["mAP50_95"]["mean"]
    assert d["se_images"] == pytest.approx(np.sqrt(d["se"] ** 2 + 2 * 0.01 ** 2), abs=1e-6)
    assert d["interval"] == pytest.approx([(d["delta"] - 2 * d["se_images"]) / gs,
                                           (d["delta"] + 2 * d["se_images"]) / gs], abs=1e-5)
    assert d["beyond_images"] is True and "interval" not in agg["label_arm"]["fast"]["hand"]["gs_to_rs"]["mAP50"]

    # the same drop, from test splits so small that their sampling alone could make it: not the pattern
    for r in results:
        for cell in r["test"].values():
            cell["mAP50_95_se"] = 0.08
    hand = next(t for t in label_statements(aggregate(QUICK, results)) if "hand-like labels" in t)
    assert "(beyond the spread; with the test images' sampling" in hand
    assert hand.endswith("does not show the study's pattern.")
    assert agg["label_arm"]["fast"]["hand"]["on_exact"]["mAP50"]["mean"] == pytest.approx(0.79)
    assert agg["label_arm"]["fast"]["hand"]["se_test"]["mean"] == pytest.approx(0.01)


def test_difference_charts_error_bars_carry_the_test_images_for_map50_95_and_the_seeds_for_map50():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.container import ErrorbarContainer
    from rollcam.host.training.study_report import _plot_label_arm, _plot_penalty

    results = []
    for seed, jitter in enumerate((0.0, 0.004, -0.004)):
        for key, group, train, test, kw in (
                ("fast_gs", "t1", "fast_gs", {"gs": _cell(0.80 + jitter)}, {}),
                ("fast_rs", "t1", "fast_rs", {"rs": _cell(0.80 - jitter)}, {}),
                ("fast_rs_handlabels", "labels", "fast_rs",
                 {"rs": _cell(0.80 + jitter) | {"mAP50_95": 0.30 + jitter}, "rs_exact": _cell(0.79)},
                 {"labels": "hand"})):
            results.append({"job": {"key": f"{key}_s{seed}", "group": group, "speed": "fast", "train": [train],
                                    "seed": seed, "raw": False, "scenes": None, "cameras": None} | kw,
                            "test": test})
    agg = aggregate(QUICK, results)
    arms = {sp: row for sp, row in agg["label_arm"].items() if row["gs_model"]["mAP50"]["n"]}
    fig, (ax, pen) = plt.subplots(1, 2)
    _plot_label_arm(ax, arms)
    _plot_penalty(pen, agg)
    bars = [c for c in ax.containers if isinstance(c, ErrorbarContainer)]
    half = [float(np.ptp(c.lines[2][0].get_segments()[0][:, 1])) / 2 for c in bars]
    lines = {c.get_label(): float(np.ptp(c.lines[2][0].get_segments()[0][:, 1])) / 2
             for c in pen.containers if isinstance(c, ErrorbarContainer)}
    plt.close(fig)
    exact, gs_cell = agg["speed"]["fast"]["gs_to_rs"], agg["speed"]["fast"]["gs"]
    assert lines["RGB mAP50"] == pytest.approx(100 * exact["mAP50"]["se"] / gs_cell["mAP50"]["mean"], rel=1e-4)
    assert lines["RGB mAP50_95"] == pytest.approx(100 * exact["mAP50_95"]["se_images"] / gs_cell["mAP50_95"]["mean"],
                                                  rel=1e-4)
    hand = arms["fast"]["hand"]["gs_to_rs"]
    gs = arms["fast"]["gs_model"]
    assert len(bars) == 6  # exact, gs, hand x mAP@0.5, mAP@0.5:0.95 (the gs arm has no runs: zero-height bars)
    assert half[4] == pytest.approx(100 * hand["mAP50"]["se"] / gs["mAP50"]["mean"], rel=1e-4)
    assert half[5] == pytest.approx(100 * hand["mAP50_95"]["se_images"] / gs["mAP50_95"]["mean"], rel=1e-4)
    assert hand["mAP50_95"]["se_images"] > 2 * hand["mAP50_95"]["se"]  # the test images' term is what shows


def test_bootstrap_se_is_zero_for_a_perfect_detector_and_grows_with_fewer_images():
    rng = np.random.default_rng(1)
    truths = [Truth.of(_boxes(5, rng), [0] * 5, None, 640, 360) for _ in range(60)]
    perfect = [Dets.of(t.boxes, np.ones(5), [0] * 5) for t in truths]
    assert bootstrap_se(truths, perfect, 20, np.random.default_rng(0)) == pytest.approx(0.0, abs=1e-9)
    noisy = [Dets.of(ANNOTATOR.draw(t.boxes, rng), rng.uniform(0.1, 1, 5), [0] * 5) for t in truths]
    many = bootstrap_se(truths, noisy, 40, np.random.default_rng(0))
    few = bootstrap_se(truths[:15], noisy[:15], 40, np.random.default_rng(0))
    assert 0 < many < few


def test_study_device_cuda_without_a_gpu_is_one_line_exit_2(tmp_path, capsys):
    torch = pytest.importorskip("torch")
    if torch.cuda.is_available():
        pytest.skip("this torch sees a GPU")
    assert main(["study", "--quick", "--device", "cuda", "--out", str(tmp_path / "s")]) == 2
    err = [line for line in capsys.readouterr().err.strip().splitlines() if line.startswith("rollcam: error:")]
    assert len(err) == 1 and "--device cuda" in err[0] and "CUDA" in err[0]


@pytest.mark.slow
def test_quick_label_arm_with_a_base_end_to_end(tmp_path, monkeypatch):
    """The label arm and Table 2 on the quick setting, every run fine-tuned from a base trained on GS images of
    other scenes; then --report rebuilds the same tables from the finished runs."""
    pytest.importorskip("torch")
    import dataclasses
    import json
    import shutil

    from rollcam.host.training import study, trainer
    from rollcam.host.training.study import run_study

    s = dataclasses.replace(QUICK, base_frames=8, base_scenes=6, base_epochs=2, base_lr=4e-3)
    out = tmp_path / "study"
    doc = run_study(s, out, only=("labels", "coco"), progress=False)
    keys = {r["job"]["key"] for r in doc["runs"]}
    assert "base" in keys and {"fast_rs_gslabels_s0", "fast_rs_handlabels_s2", "fast_gs_s1", "fast_rs_s0"} <= keys
    assert not any(k.startswith("normal") for k in keys)
    card = json.loads((out / "runs" / "fast_rs_handlabels_s0" / "train.json").read_text())
    assert card["config"]["labels"] == "hand" and card["config"]["init"].endswith("runs/base/last.pt")
    base = json.loads((out / "data" / "base" / "dataset.json").read_text())
    assert base["config"]["seed"] == 1 and list(base["subsets"]) == ["normal_gs", "normal_rs"]
    run = json.loads((out / "runs" / "fast_rs_handlabels_s0" / "test.json").read_text())
    assert {"gs", "rs", "gsrs", "rs_exact"} <= set(run["test"]) and "mAP50_95_se" in run["test"]["rs"]
    boxes = doc["labels"]["boxes"]["fast"]
    assert boxes["hand"]["mean_area_px2"] < boxes["exact"]["mean_area_px2"]
    assert set(doc["labels"]["ceiling"]["fast"]) == {"exact", "gs", "hand", "hand_inset"}
    assert set(doc["coco"]) == {"ssdlite", "hog"} and "rs_handlabels" in doc["coco"]["ssdlite"]["fast"]
    text = (out / "report.md").read_text()
    assert "## The label arm" in text and "## Table 2 analogue" in text and "hand-like labels" in text
    again = run_study(s, out, only=("labels", "coco"), report_only=True)
    assert again["label_arm"] == doc["label_arm"] and again["timing"]["finished"] == len(doc["runs"])

    # carried on elsewhere from the report folder alone: the datasets are rendered again and match, every run and
    # Table 2 are taken over, nothing is trained
    carried = tmp_path / "committed"
    carried.mkdir()
    for name in ("report.json", "base.pt"):
        shutil.copy(out / name, carried / name)
    monkeypatch.setattr(trainer, "train", lambda *a, **k: pytest.fail("an adopted run was trained again"))
    monkeypatch.setattr(study, "test_model", lambda *a, **k: pytest.fail("a model was tested again"))
    other = run_study(s, tmp_path / "elsewhere", only=("labels", "coco"), progress=False, adopt_from=(carried,))
    assert other["label_arm"] == doc["label_arm"] and other["datasets"] == doc["datasets"]
    assert [r["test"] for r in other["runs"]] == [r["test"] for r in doc["runs"]]
