"""``personnet-raw``: rollcam's person detector trained on the raw Bayer mosaic (no ISP), shipped as ONNX.

The same anchor-free PersonNet as ``personnet`` (docs/training.md), trained by ``rollcam train --input raw`` on
the 8-bit RGGB mosaics of rollcam's study camera (``letsroll``, 320x180, fast walkers, both shutters), so it is
the network an intelligent sensor runs on what its pixels give: the emulated camera's default in-sensor network
(``emu:letsroll?size=320x180&insensor=personnet-raw``, docs/insensor.md). ``tools/train_personnet_raw.sh``
rebuilds it; its card, figures and licence sit beside it in ``models/personnet_raw/``. It takes the mosaic
letterboxed to its 320x180 input, scaled by the model's own bit depth (``rollcam_bits``); options are those of
``onnx:`` that do not describe the model (``conf``, default the card's best-F1 threshold; ``iou``, ``max_det``,
``threads``; ``tiles`` only with tiles of the mosaic's scale).
"""

from __future__ import annotations

import json

from rollcam.common.errors import ConfigError

from .base import DetectorSpec
from .onnx import OnnxDetector
from .packaged import open_packaged, packaged_model

MODEL_DIR = "models/personnet_raw"
CARD = "personnet_raw.json"
REBUILD = "tools/train_personnet_raw.sh"


def card() -> dict:
    """The packaged model's JSON card: its training run (``training``) and measured figures (``figures``)."""
    path = packaged_model(MODEL_DIR, "personnet-raw", REBUILD).with_name(CARD)
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ConfigError(f"the personnet-raw card {str(path)!r} is missing or unreadable ({exc}); reinstall "
                          f"rollcam or regenerate it with {REBUILD}") from None


def open_detector(spec: DetectorSpec) -> OnnxDetector:
    """Build the packaged raw-mosaic person detector from ``personnet-raw?conf=..``."""
    defaults = {} if "conf" in spec.options else {"conf": float(card()["figures"]["conf"])}
    return open_packaged(spec, name="personnet-raw", model_dir=MODEL_DIR, rebuild=REBUILD, defaults=defaults,
                         fixed={"layout": "yolo", "class_offset": 0, "letterbox_input": True, "bgr": False,
                                "input": "raw"})
