"""Which Raspberry Pi the camera is on: the stand-in is a Pi 4 (``Platform.VC4``: lores is YUV, as there)."""

from __future__ import annotations

import enum


class Platform(enum.Enum):
    """picamera2's platforms: VC4 (Pi 4 and earlier, the Broadcom ISP) and PISP (Pi 5)."""

    VC4 = 0
    PISP = 1


def get_platform() -> Platform:
    """The platform the stand-in emulates: VC4."""
    return Platform.VC4
