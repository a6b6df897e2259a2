"""Detectors behind one small protocol: an image in; boxes, scores and classes out.

``load_detector(spec)`` resolves a spec such as ``hog``, ``hog?scale=1.1&stride=4`` or ``onnx:model.onnx?conf=0.3``
the way sources resolve URIs: the name before ``:``/``?`` picks a module ``rollcam.host.detectors.<name>`` whose
``open_detector(spec: DetectorSpec)`` builds the detector. A new detector is one new module plus its name in
``DETECTORS``. Nothing else in ``host`` imports a concrete detector.
"""

from __future__ import annotations

import importlib

from rollcam.common.errors import ConfigError

from .base import PERSON, Detections, Detector, DetectorSpec, parse_spec

DETECTORS = {"hog": "hog", "insensor": "insensor", "onnx": "onnx", "personnet": "personnet",
             "personnet-raw": "personnet_raw", "ssdlite": "ssdlite"}
"""Detector name -> module name under ``rollcam.host.detectors``."""


def load_detector(spec: str) -> Detector:
    """Build the detector named by ``spec`` (``NAME[:TARGET][?key=value&...]``)."""
    parts = parse_spec(spec)
    module_name = DETECTORS.get(parts.name)
    if module_name is None:
        raise ConfigError(f"detector {spec!r}: unknown detector {parts.name!r}; known: {sorted(DETECTORS)}")
    module = importlib.import_module(f"{__name__}.{module_name}")
    return module.open_detector(parts)


__all__ = ["DETECTORS", "PERSON", "Detections", "Detector", "DetectorSpec", "load_detector", "parse_spec"]
