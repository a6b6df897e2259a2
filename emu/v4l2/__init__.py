"""A V4L2-like emulated camera in three layers: ``raw`` (kernel constants and structures), ``functions``
(plain calls on a handle) and ``device`` (the ``Device`` class); ``driver`` is the kernel side."""

from .device import CapturedBuffer, ControlHandle, Device
from .driver import EmuDriver
from .queue import V4L2Error

__all__ = ["CapturedBuffer", "ControlHandle", "Device", "EmuDriver", "V4L2Error"]
