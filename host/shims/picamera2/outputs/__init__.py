"""picamera2's outputs: where encoders send frames (``FileOutput``, ``FfmpegOutput``, ``CircularOutput``)."""

from .circularoutput import CircularOutput
from .ffmpegoutput import FfmpegOutput
from .fileoutput import FileOutput
from .output import Output

__all__ = ["CircularOutput", "FfmpegOutput", "FileOutput", "Output"]
