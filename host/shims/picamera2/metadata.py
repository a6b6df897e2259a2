"""``Metadata``: a frame's metadata dictionary as an object with attributes (``md.ExposureTime``)."""

from __future__ import annotations

from typing import Any


class Metadata:
    """The keys of a metadata dictionary as attributes."""

    def __init__(self, metadata: dict[str, Any] | None = None) -> None:
        self.__dict__ = dict(metadata or {})

    def __repr__(self) -> str:
        return f"<Metadata: {self.__dict__}>"

    def make_dict(self) -> dict[str, Any]:
        """The dictionary back."""
        return self.__dict__.copy()
