"""Host side: camera sources, CLI. ``from rollcam.host import open_camera`` opens any source URI."""

from rollcam.sim.errors import ConfigError, DeviceError, ProtocolError, RollcamError, SourceError

from .sources import open_camera

__all__ = ["ConfigError", "DeviceError", "ProtocolError", "RollcamError", "SourceError", "open_camera"]
