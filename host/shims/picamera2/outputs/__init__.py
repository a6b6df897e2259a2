"""picamera2's outputs: where encoders send frames (``FileOutput``, ``FfmpegOutput``, ``PyavOutput``,
``CircularOutput``, ``CircularOutput2``, ``SplittableOutput``)."""

from .circularoutput import CircularOutput
from .circularoutput2 import CircularOutput2
from .ffmpegoutput import FfmpegOutput, PyavOutput
from .fileoutput import FileOutput
from .output import Output
from .splittableoutput import SplittableOutput

__all__ = ["CircularOutput", "CircularOutput2", "FfmpegOutput", "FileOutput", "Output", "PyavOutput",
           "SplittableOutput"]
