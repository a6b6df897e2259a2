"""``SensorFormat``: a raw format name (``SRGGB10_CSI2P``) taken apart into Bayer order, bit depth and packing."""

from __future__ import annotations

import re

_NAME = re.compile(r"^(?:S(?P<order>[RGB]{4})(?P<bits>\d+)|R(?P<mono>\d+))(?:_(?P<packing>[A-Z0-9_]+))?$")


class SensorFormat:
    """A raw sensor format: ``bayer_order`` ('RGGB', or 'R' for mono), ``bit_depth``, ``packing`` (None,
    'CSI2P', 'PISP_COMP1'); ``format`` and ``unpacked`` give the names back."""

    def __init__(self, fmt_string: str) -> None:
        if fmt_string.endswith("_PISP_COMP1") or fmt_string.endswith("_PISP_COMP2"):
            order, self.packing = fmt_string.split("_", 1)
            self.bayer_order, self.bit_depth = order, 16
            return
        m = _NAME.match(str(fmt_string))
        if m is None:
            raise ValueError(f"{fmt_string!r} is not a raw sensor format (SRGGB10_CSI2P, SBGGR12, R8, ...)")
        self.packing = m["packing"]
        self.bayer_order = "R" if m["mono"] else m["order"]
        self.bit_depth = int(m["mono"] or m["bits"])

    @property
    def mono(self) -> bool:
        """True for a monochrome sensor's format."""
        return self.bayer_order == "R"

    @property
    def unpacked(self) -> str:
        """The name without packing (``SRGGB10``)."""
        return f"{'' if self.mono else 'S'}{self.bayer_order}{self.bit_depth}"

    @property
    def format(self) -> str:
        """The full name (``SRGGB10_CSI2P``)."""
        return self.unpacked + (f"_{self.packing}" if self.packing else "")

    def __repr__(self) -> str:
        return self.format

    def __str__(self) -> str:
        return self.format

    def __eq__(self, other: object) -> bool:
        return str(other) == self.format if isinstance(other, (str, SensorFormat)) else NotImplemented

    def __hash__(self) -> int:
        return hash(self.format)

    def transform(self, transform: object) -> None:
        """Change the Bayer order as flips (``transform.hflip``/``vflip``) change what the readout starts on."""
        if self.mono:
            return
        rows = [self.bayer_order[:2], self.bayer_order[2:]]
        if getattr(transform, "vflip", False):
            rows = rows[::-1]
        if getattr(transform, "hflip", False):
            rows = [r[::-1] for r in rows]
        self.bayer_order = "".join(rows)
