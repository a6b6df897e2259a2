"""``train``: fit the person detector on a rollcam dataset, checkpoint every epoch, export ONNX, write a card.

Deterministic on CPU for a seed and a thread count: the weights start from ``torch.manual_seed(seed)``, each
epoch's order and augmentation come from ``numpy.random.default_rng([seed, epoch])``, the learning rate is a
function of the step number, and torch runs with ``use_deterministic_algorithms`` and a fixed number of threads.
So a run resumed from its checkpoint (``last.pt``, written atomically after every epoch, holding weights,
optimiser state and history) ends with the same weights as one never interrupted. Rerunning into a folder whose
checkpoint was made with other options is refused, naming the options that differ.

Validation, every ``val_every`` epochs, exports the model and scores it through the ``onnx:`` detector on the
validation split, so the curve shows what ``rollcam eval`` will report, not a second decoder's opinion.
"""

from __future__ import annotations

import io
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from rollcam.common.errors import ConfigError, require
from rollcam.common.files import write_atomic

from ..progress import Progress
from .config import TrainConfig
from .data import DatasetInfo, FittedImages, check_subsets, load_split, make_batch, open_dataset

CHECKPOINT = "last.pt"
MODEL_FILE = "model.onnx"
VAL_MODEL = ".val.onnx"
VAL_CONF = 0.01
"""Score threshold of validation: low, as mAP wants the whole precision-recall curve."""
WARMUP_STEPS = 100


@dataclass
class TrainResult:
    """What a run did: its folder, exported model, epochs done, the epoch it resumed after, history, card."""

    out_dir: Path
    model_path: Path
    epochs: int
    resumed_after: int
    seconds: float
    history: list[dict[str, Any]] = field(default_factory=list)
    card: dict[str, Any] = field(default_factory=dict)


def import_torch() -> Any:
    """torch, or the missing-dependency error naming the ``train`` extra."""
    return require("torch", "torch", "train", "rollcam train")


def learning_rate(cfg: TrainConfig, step: int, total: int) -> float:
    """Linear warm-up over the first steps, then a cosine from ``lr`` down to 5 % of it."""
    warm = min(WARMUP_STEPS, max(total // 10, 1))
    if step < warm:
        return cfg.lr * (0.1 + 0.9 * step / warm)
    t = (step - warm) / max(total - warm, 1)
    return cfg.lr * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * min(t, 1.0))))


def resolve_device(device: str) -> str:
    """``auto`` -> ``cuda`` when torch sees a GPU, else ``cpu``; ``cpu``/``cuda`` are checked."""
    torch = import_torch()
    if device == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if device == "cuda" and not torch.cuda.is_available():
        raise ConfigError("--device cuda: this torch sees no CUDA GPU (install a CUDA build of torch)")
    if device not in ("cpu", "cuda"):
        raise ConfigError(f"--device {device!r} is not one of ['auto', 'cpu', 'cuda']")
    return device


def _check_dataset(cfg: TrainConfig) -> tuple[DatasetInfo, tuple[str, ...], tuple[str, ...]]:
    info = open_dataset(cfg.dataset)
    if cfg.input == "raw" and not info.raw_format:
        raise ConfigError(f"--input raw needs a dataset of raw mosaics; {cfg.dataset!r} holds pictures (build it "
                          "with 'rollcam dataset --raw RGGB')")
    if cfg.input == "rgb" and info.raw_format:
        raise ConfigError(f"dataset {cfg.dataset!r} holds raw {info.raw_format} mosaics; train on it with --input raw")
    subsets = check_subsets(info, cfg.subsets, "--subset")
    return info, subsets, check_subsets(info, cfg.val_subsets or subsets, "--val")


def load_state(path: Path) -> dict[str, Any]:
    """A checkpoint (``last.pt``) or a bare state dict saved by torch, on the CPU; a file that is neither is a
    ``ConfigError`` naming it."""
    torch = import_torch()
    try:
        return torch.load(str(path), map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises a zoo of errors for files that are not its checkpoints
        raise ConfigError(f"{str(path)!r} is not a readable rollcam training checkpoint: {exc}") from None


def _checkpoint(out: Path, cfg: TrainConfig) -> dict[str, Any] | None:
    """The run's checkpoint when it has one made with ``cfg``; a ConfigError when it was made with another."""
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {str(out)!r} exists and is not a directory")
    path = out / CHECKPOINT
    if not path.is_file():
        return None
    state = load_state(path)
    have, want = TrainConfig.added_keys() | state.get("config", {}), cfg.to_json()
    if have != want:
        diff = sorted(k for k in set(have) | set(want) if have.get(k) != want.get(k))
        raise ConfigError(f"{str(out)!r} holds a run trained with other options (differing: {diff}); choose "
                          "another --out, or delete its last.pt to start over")
    return state


CALIBRATION_IMAGES = 64
"""Training images (in file order, no augmentation) that re-estimate BatchNorm statistics for an ONNX ``--init``."""


def _init_weights(net: Any, path: str, images: FittedImages, cfg: TrainConfig, bits: int | None) -> None:
    """Start ``net`` from ``path``: a checkpoint (``last.pt``), a bare state dict, or a ``model.onnx`` of
    ``rollcam train`` (the shipped detectors have only that), whose BatchNorms are rebuilt from ``images``."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"--init {path!r} does not exist")
    if p.suffix.lower() == ".onnx":
        torch = import_torch()
        from .export import load_onnx_weights

        n = min(len(images), CALIBRATION_IMAGES)
        batches = (torch.from_numpy(make_batch(images, np.arange(i, min(i + cfg.batch, n)), None, bits)["image"])
                   for i in range(0, n, cfg.batch))
        load_onnx_weights(net, p, batches)
        return
    state = load_state(p)
    weights = state.get("model", state) if isinstance(state, dict) else state
    try:
        net.load_state_dict(weights)
    except (RuntimeError, TypeError, AttributeError) as exc:
        raise ConfigError(f"--init {path!r} does not fit this model ({str(exc).splitlines()[0]})") from None


def save_state(path: Path, state: dict[str, Any]) -> None:
    """Write what torch saves of ``state`` to ``path`` atomically (whole or absent), ``load_state``'s twin."""
    torch = import_torch()
    buf = io.BytesIO()
    torch.save(state, buf)
    write_atomic(path, buf.getvalue())


def _optimizer(net: Any, cfg: TrainConfig) -> Any:
    torch = import_torch()
    decay = [p for p in net.parameters() if p.ndim > 1]
    rest = [p for p in net.parameters() if p.ndim <= 1]
    return torch.optim.AdamW([{"params": decay, "weight_decay": cfg.weight_decay},
                              {"params": rest, "weight_decay": 0.0}], lr=cfg.lr)


class WeightAverage:
    """An exponential moving average of a network's weights and BatchNorm statistics, the model that
    validation and the export use when ``--ema`` is on. Its decay ramps in as ``min(decay, (1 + n) / (10 + n))``
    over the first updates n, so it follows the weights closely early in a run and averages over the last
    ~1 / (1 - decay) steps once the ramp has passed."""

    def __init__(self, net: Any, decay: float) -> None:
        import copy

        self.decay = decay
        self.updates = 0
        self.net = copy.deepcopy(net).eval()
        for p in self.net.parameters():
            p.requires_grad_(False)

    def update(self, net: Any) -> None:
        """Fold ``net``'s current weights into the average (after an optimiser step)."""
        torch = import_torch()
        self.updates += 1
        d = min(self.decay, (1 + self.updates) / (10 + self.updates))
        with torch.no_grad():
            current = net.state_dict()
            for key, avg in self.net.state_dict().items():
                if avg.dtype.is_floating_point:
                    avg.mul_(d).add_(current[key].detach(), alpha=1 - d)
                else:
                    avg.copy_(current[key])

    def state(self) -> dict[str, Any]:
        """What a checkpoint keeps of it."""
        return {"weights": self.net.state_dict(), "updates": self.updates}

    def load(self, state: dict[str, Any]) -> None:
        """Restore it from ``state()`` of a checkpoint."""
        self.net.load_state_dict(state["weights"])
        self.updates = int(state["updates"])


def validate(model_path: Path, sets: list[Any], threads: int) -> dict[str, Any]:
    """P, R, mAP50 and mAP50_95 of an exported model over ``sets`` together (through ``onnx:``)."""
    from ..detectors import load_detector
    from ..evaluation.loaders import run_detector
    from ..evaluation.metrics import evaluate

    det = load_detector(f"onnx:{model_path}?conf={VAL_CONF}&threads={threads}")
    try:
        dets = [d for s in sets for d in run_detector(det, s)]
    finally:
        det.close()
    m = evaluate([e.truth for s in sets for e in s.images], dets)
    return {k: round(float(m[k]), 6) for k in ("P", "R", "mAP50", "mAP50_95")}


@dataclass
class _Run:
    """The moving parts of one run, set up by ``train``."""

    cfg: TrainConfig
    out: Path
    info: DatasetInfo
    net: Any
    opt: Any
    device: str
    images: FittedImages
    val_sets: list[Any]
    history: list[dict[str, Any]]
    steps_per_epoch: int
    average: WeightAverage | None = None

    @property
    def final_net(self) -> Any:
        """The network that is validated and exported: the weight average when there is one."""
        return self.average.net if self.average is not None else self.net


def _epoch(run: _Run, epoch: int, bar: Progress, clock: Callable[[], float]) -> dict[str, Any]:
    torch = import_torch()
    from .loss import detector_loss

    cfg = run.cfg
    rng = np.random.default_rng([cfg.seed, epoch])
    order = rng.permutation(len(run.images))
    total = cfg.epochs * run.steps_per_epoch
    t0 = clock()
    sums = {"loss": 0.0, "heat": 0.0, "box": 0.0}
    run.net.train()
    for k in range(run.steps_per_epoch):
        step = epoch * run.steps_per_epoch + k
        lr = learning_rate(cfg, step, total)
        for g in run.opt.param_groups:
            g["lr"] = lr
        idx = order[(k * cfg.batch) % len(order):][:cfg.batch]
        if len(idx) < min(cfg.batch, len(order)):  # wrap around: every batch is full
            idx = np.concatenate([idx, order[:cfg.batch - len(idx)]])
        batch = {key: torch.from_numpy(v).to(run.device) for key, v in make_batch(
            run.images, idx, rng, run.info.raw_bits).items()}
        loss, parts = detector_loss(run.net(batch["image"]), batch)
        run.opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(run.net.parameters(), 10.0)
        run.opt.step()
        if run.average is not None:
            run.average.update(run.net)
        sums["loss"] += float(loss.detach())
        sums["heat"] += parts["heat"]
        sums["box"] += parts["box"]
        bar.update(step + 1)
        bar.status(f"epoch {epoch + 1}/{cfg.epochs} loss {sums['loss'] / (k + 1):.3f}" + _last_val(run.history),
                   refresh=False)
    row: dict[str, Any] = {"epoch": epoch + 1, "lr": round(lr, 8),
                           **{key: round(v / run.steps_per_epoch, 6) for key, v in sums.items()}}
    if (epoch + 1) % cfg.val_every == 0 or epoch + 1 == cfg.epochs:
        from .export import export_onnx

        export_onnx(run.final_net, run.out / VAL_MODEL, *cfg.imgsz, input=cfg.detector_input, bits=run.info.raw_bits)
        row["val"] = validate(run.out / VAL_MODEL, run.val_sets, cfg.threads)
    row["seconds"] = round(clock() - t0, 3)
    return row


def _last_val(history: list[dict[str, Any]]) -> str:
    vals = [h["val"] for h in history if "val" in h]
    return f" val mAP50 {vals[-1]['mAP50']:.3f} mAP50-95 {vals[-1]['mAP50_95']:.3f}" if vals else ""


def train(cfg: TrainConfig, out_dir: str | Path, *, device: str = "cpu", progress: bool | None = None,
          stream: TextIO | None = None, on_epoch: Callable[[int], None] | None = None,
          clock: Callable[[], float] = time.monotonic, argv: list[str] | None = None) -> TrainResult:
    """Train (or resume training) into ``out_dir``; ``on_epoch(n)`` is called after epoch n's checkpoint is
    written (a seam for tests that interrupt a run); ``argv`` is recorded in the card."""
    torch = import_torch()
    out = Path(out_dir)
    info, subsets, val_subsets = _check_dataset(cfg)
    state = _checkpoint(out, cfg)
    device = resolve_device(device)
    prev_threads, prev_det = torch.get_num_threads(), torch.are_deterministic_algorithms_enabled()
    torch.set_num_threads(cfg.threads)
    torch.use_deterministic_algorithms(device == "cpu")
    try:
        return _train(cfg, out, info, subsets, val_subsets, state, device, progress, stream, on_epoch, clock, argv)
    finally:
        torch.set_num_threads(prev_threads)
        torch.use_deterministic_algorithms(prev_det)


def _train(cfg: TrainConfig, out: Path, info: DatasetInfo, subsets: tuple[str, ...], val_subsets: tuple[str, ...],
           state: dict[str, Any] | None, device: str, progress: bool | None, stream: TextIO | None,
           on_epoch: Callable[[int], None] | None, clock: Callable[[], float], argv: list[str] | None) -> TrainResult:
    torch = import_torch()
    from .card import write_card
    from .export import export_onnx
    from .model import PersonNet, model_size

    torch.manual_seed(cfg.seed)
    net = PersonNet(model_size(cfg.model), in_channels=1 if cfg.input == "raw" else 3)
    images = FittedImages(load_split(info, subsets, "train", scenes=cfg.scenes, cameras=cfg.cameras,
                                     labels=cfg.labels), *cfg.imgsz,
                          cfg.detector_input).with_backgrounds(cfg.background, cfg.seed, info.card,
                                                               cfg.background_kinds)
    if not images.entries:
        raise ConfigError(f"the train split of {list(subsets)} in {cfg.dataset!r} holds no images")
    if cfg.init and state is None:
        _init_weights(net, cfg.init, images, cfg, info.raw_bits)
    net.to(device)
    opt = _optimizer(net, cfg)
    history: list[dict[str, Any]] = []
    if state is not None:
        net.load_state_dict(state["model"])
        opt.load_state_dict(state["optimizer"])
        history = list(state["history"])
    average = WeightAverage(net, cfg.ema) if cfg.ema else None
    if average is not None and state is not None:
        average.load(state["ema"])
    steps = max(1, math.ceil(len(images) / cfg.batch))
    steps = min(steps, cfg.steps) if cfg.steps else steps
    val_sets = load_split(info, val_subsets, "val", labels=cfg.labels)
    run = _Run(cfg, out, info, net, opt, device, images, val_sets, history, steps, average)
    out.mkdir(parents=True, exist_ok=True)
    done = len(history)
    t_start = clock()
    bar = Progress(cfg.epochs * steps, label=f"train {cfg.model}", stream=stream, enabled=progress, unit="step")
    bar.update(done * steps)
    try:
        for epoch in range(done, cfg.epochs):
            history.append(_epoch(run, epoch, bar, clock))
            save_state(out / CHECKPOINT, {"config": cfg.to_json(), "epoch": epoch + 1, "model": net.state_dict(),
                                     "optimizer": opt.state_dict(), "history": history}
                  | ({"ema": average.state()} if average is not None else {}))
            if on_epoch is not None:
                on_epoch(epoch + 1)
    finally:
        bar.close()
    final = run.final_net.to("cpu")
    model_path = export_onnx(final, out / MODEL_FILE, *cfg.imgsz, input=cfg.detector_input, bits=info.raw_bits,
                             info={"size": cfg.model, "imgsz": cfg.to_json()["imgsz"], "input": cfg.input})
    (out / VAL_MODEL).unlink(missing_ok=True)
    seconds = clock() - t_start
    card = write_card(out, cfg, info, subsets, val_subsets, final, history, device=device, resumed_after=done,
                      seconds=seconds, argv=argv)
    return TrainResult(out, model_path, cfg.epochs, done, seconds, history, card)
