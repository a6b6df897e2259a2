"""Camera sources, one module per URI scheme, resolved by name (as pyserial resolves ``protocol_<scheme>``).

``open_camera(uri)`` imports ``rollcam.host.sources.<scheme>`` and calls its ``open_source(parts)``;
a new backend is one new module plus its name in ``SCHEMES``. Nothing else in ``host`` imports a backend.
"""

from __future__ import annotations

import importlib

from rollcam.common.errors import SourceError
from rollcam.common.values import parse_query

from .base import CameraSource, SourceURI

SCHEMES = {"emu": "emu", "file": "file", "http": "http", "https": "http", "opencv": "opencv", "v4l2": "v4l2",
           "oak": "oak", "uvc": "uvc"}
"""URI scheme -> module name under ``rollcam.host.sources``."""


def parse_uri(uri: str) -> SourceURI:
    """Split ``scheme:target?key=value&...`` into its parts; duplicate or empty keys are errors."""
    if not isinstance(uri, str) or ":" not in uri:
        raise SourceError(f"source {uri!r} is not a URI; expected one of {[s + ':...' for s in SCHEMES]}")
    scheme, rest = uri.split(":", 1)
    scheme = scheme.lower()
    if scheme in ("http", "https"):
        return SourceURI(uri, scheme, uri, {})
    target, _, query = rest.partition("?")
    options = parse_query(query, f"source {uri!r}", SourceError)
    return SourceURI(uri, scheme, target, options)


def open_camera(uri: str) -> CameraSource:
    """Open any supported camera source by URI (see DESIGN.md: ``emu:imx219?scene=street``, ``file:DIR``)."""
    parts = parse_uri(uri)
    module_name = SCHEMES.get(parts.scheme)
    if module_name is None:
        raise SourceError(f"source {uri!r}: scheme {parts.scheme!r} is not supported; known: {sorted(SCHEMES)}")
    module = importlib.import_module(f"{__name__}.{module_name}")
    return module.open_source(parts)


__all__ = ["SCHEMES", "CameraSource", "SourceURI", "open_camera", "parse_uri"]
