"""The one exception tree of rollcam; every part raises these (re-exported by ``rollcam.host``)."""

from __future__ import annotations


class RollcamError(Exception):
    """Root of every error rollcam raises on purpose."""


class ConfigError(RollcamError, ValueError):
    """A sensor description, scene option or other configuration is invalid."""


class SourceError(RollcamError):
    """A camera source cannot be opened or read (bad URI, missing backend, corrupt file)."""


class DeviceError(RollcamError):
    """An emulated or real device refused an operation."""


class ProtocolError(RollcamError):
    """A peer sent a malformed request on a control or transport protocol."""
