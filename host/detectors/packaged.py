"""Detectors shipped with rollcam as ONNX files under ``models/``: where the file is, and the options they fix.

``ssdlite`` and ``personnet`` are each an ``onnx:`` detector on a packaged model whose layout, colour order and
scaling are properties of the model, not choices: ``open_packaged`` refuses those options, refuses a target,
applies the model's defaults (e.g. its score threshold) and finds the file in the installation.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

from rollcam.common.errors import ConfigError

from .base import PERSON, DetectorSpec
from .onnx import OnnxDetector, detector_options

FIXED = frozenset({"layout", "box", "class_offset", "size", "letterbox", "bgr", "input", "norm", "bits"})
"""``onnx:`` options that describe the model itself and so are fixed by a packaged model."""


def packaged_model(model_dir: str, name: str, rebuild: str) -> Path:
    """The packaged ``models/<model_dir>/model.onnx``; a ConfigError saying how to get it back when absent."""
    path = Path(str(resources.files("rollcam.host.detectors").joinpath(model_dir, "model.onnx")))
    if not path.is_file():
        raise ConfigError(f"the {name} model is missing from this installation ({str(path)!r}); reinstall rollcam "
                          f"or regenerate it with {rebuild}")
    return path


def open_packaged(spec: DetectorSpec, *, name: str, model_dir: str, rebuild: str, fixed: dict[str, Any],
                  defaults: dict[str, Any]) -> OnnxDetector:
    """The ``onnx:`` detector of a packaged person model: ``fixed`` keyword arguments of ``OnnxDetector`` set by
    the model, ``defaults`` used where the spec does not set them (keys are ``onnx:`` option names)."""
    bad = FIXED & set(spec.options)
    if bad:
        raise ConfigError(f"detector {spec.spec!r}: option(s) {sorted(bad)} are fixed by the {name} model")
    if spec.target:
        raise ConfigError(f"detector {spec.spec!r}: {name} takes no target (got {spec.target!r})")
    kw = detector_options(spec)
    for key, value in defaults.items():
        if key not in spec.options:
            kw[key] = value
    kw.update(fixed)
    if kw["classes"] is None:
        kw["classes"] = (PERSON,)
    return OnnxDetector(packaged_model(model_dir, name, rebuild), name=name, class_names={PERSON: "person"}, **kw)
