"""What every camera source offers: Frames in order, context management, controls where the device has them."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from rollcam.common.errors import SourceError
from rollcam.common.lifecycle import Closeable
from rollcam.common.values import (  # noqa: F401  (the value parsers are re-exported for the source modules)
    convert_option,
    finite_float,
    non_negative_float,
    non_negative_int,
    parse_host_port,
    parse_size,
    positive_float,
    positive_int,
    reject_unknown,
)
from rollcam.sim.frame import Frame


@dataclass(frozen=True)
class SourceURI:
    """A parsed source URI: scheme, target (sensor name, path, device) and query options."""

    uri: str
    scheme: str
    target: str
    options: dict[str, str] = field(default_factory=dict)

    def take(self, used: set[str], allowed: set[str]) -> None:
        """Reject options this scheme does not know, naming them and the ones it does."""
        reject_unknown(self.options, allowed, f"source {self.uri!r}", SourceError)
        used.update(self.options)

    def get(self, key: str, kind: Callable[[str], Any], default: Any = None) -> Any:
        """Option ``key`` converted by ``kind``, or ``default`` when absent; bad values name the option."""
        return convert_option(self.options, key, kind, default, f"source {self.uri!r}", SourceError)


class CameraSource(Closeable, ABC):
    """A stream of Frames. Iterate it, or call ``read()``; ``close()`` is idempotent; use ``with``.

    Sources release their device in ``_close()`` (run once, by the first ``close()``); ``read()`` on a
    closed source raises SourceError (``_check_open()``).
    """

    uri: str = ""
    closed_error = SourceError

    @abstractmethod
    def read(self) -> Frame | None:
        """The next frame, or None at the end of a finite source."""

    def info(self) -> dict[str, Any]:
        """What the source is (sensor, size, timing) as plain data."""
        return {"uri": self.uri}

    # Paired global/rolling frames of the same instant (synthetic and composed sources only).
    supports_pairs: bool = False

    def read_pair(self) -> tuple[Frame, Frame] | None:
        """The next (global, rolling) pair of the same instant, or None at the end."""
        raise SourceError(f"source {self.uri!r} cannot deliver paired global/rolling frames")

    def read_as(self, shutter: str) -> Frame | None:
        """The next frame under ``shutter`` ('global' or 'rolling'), or None at the end.

        This default takes one frame of ``read_pair()``; sources that render each shutter on its own
        override it so the other one is not made for nothing.
        """
        pair = self.read_pair()
        return None if pair is None else pair[0 if shutter == "global" else 1]

    def __iter__(self) -> Iterator[Frame]:
        while True:
            frame = self.read()
            if frame is None:
                return
            yield frame

    def _describe(self) -> str:
        return f"source {self.uri!r}"
