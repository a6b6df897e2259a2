"""rollcam's stand-in for picamera2: the Raspberry Pi camera library, on an emulated camera, on any machine.

Put the folder above this package first on ``sys.path`` (``PYTHONPATH=$(python -c 'import rollcam.host as h;
print(h.shims_path())')``, or ``rollcam run``, or the ``rollcam_picamera2`` pytest fixture) and ``from picamera2
import Picamera2`` gets a camera backed by ``rollcam.firmware.FirmwareCamera``. Which sensors: the environment
variable ``ROLLCAM_PICAMERA2`` (``imx219`` by default). What is covered: docs/picamera2.md.
"""

from concurrent.futures import TimeoutError  # picamera2 exports this name

import libcamera

from . import formats
from .configuration import CameraConfiguration, SensorConfiguration, StreamConfiguration
from .controls import Controls
from .job import CancelledError, Job
from .metadata import Metadata
from .picamera2 import Picamera2, Preview
from .platform import Platform, get_platform
from .remote import Pool, Process, RemoteMappedArray, RemoteRequest
from .request import CompletedRequest, MappedArray
from .sensor_format import SensorFormat

ROLLCAM_STANDIN = True
"""Marks this picamera2 as rollcam's stand-in (scripts and tests can tell it from the real one)."""

__all__ = ["CameraConfiguration", "CancelledError", "CompletedRequest", "Controls", "Job", "MappedArray",
           "Metadata", "Picamera2", "Platform", "Pool", "Preview", "Process", "RemoteMappedArray",
           "RemoteRequest", "SensorConfiguration", "SensorFormat",
           "StreamConfiguration", "TimeoutError", "formats", "get_platform", "libcamera"]
