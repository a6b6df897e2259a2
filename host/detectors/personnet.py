"""``personnet``: rollcam's own person detector, trained on rollcam's GS and RS street renders, shipped as ONNX.

The model is ``rollcam train``'s anchor-free PersonNet (plain PyTorch, MIT; docs/training.md) trained from
scratch on a rollcam dataset of both speeds and both shutters by ``tools/train_personnet.sh``; its training
card, figures and licence sit beside it in ``models/personnet/``. It letterboxes the frame to its fixed input
(RGB, 0..1) and returns person boxes; the decode (heatmap peaks, box distances) is inside the graph. Options
are those of ``onnx:`` (``conf``, default ``default_conf()``: the card's best-F1 threshold on the validation
split; ``iou``, default ``default_iou()``: the card's NMS IoU of best validation mAP; ``tiles``, ``threads``,
``max_det``).
"""

from __future__ import annotations

import json
from pathlib import Path

from rollcam.common.errors import ConfigError

from .base import DetectorSpec
from .onnx import OnnxDetector
from .packaged import open_packaged, packaged_model

MODEL_DIR = "models/personnet"
CARD = "personnet.json"
REBUILD = "tools/train_personnet.sh"


def model_path() -> Path:
    """Where the packaged ``model.onnx`` is; a ConfigError when the installation lacks it."""
    return packaged_model(MODEL_DIR, "personnet", REBUILD)


def card() -> dict:
    """The packaged model's JSON card: its training run (``training``) and measured figures (``figures``)."""
    path = model_path().with_name(CARD)
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ConfigError(f"the personnet card {str(path)!r} is missing or unreadable ({exc}); reinstall rollcam "
                          f"or regenerate it with {REBUILD}") from None


def default_conf() -> float:
    """The default score threshold: the one of best F1 on the training dataset's validation split (the card's)."""
    return float(card()["figures"]["conf"])


def default_iou() -> float:
    """The default NMS IoU threshold: the one of best mAP@0.5:0.95 on the validation split (the card's; a card
    from before it was chosen gives ``onnx:``'s 0.45)."""
    return float(card()["figures"].get("iou", 0.45))


def open_detector(spec: DetectorSpec) -> OnnxDetector:
    """Build the packaged person detector from ``personnet?conf=..&iou=..&tiles=..``."""
    defaults = {key: get() for key, get in (("conf", default_conf), ("iou", default_iou))
                if key not in spec.options}
    return open_packaged(spec, name="personnet", model_dir=MODEL_DIR, rebuild=REBUILD, defaults=defaults,
                         fixed={"layout": "yolo", "class_offset": 0, "letterbox_input": True, "bgr": False,
                                "input": "bgr"})
