"""picamera2's encoders: ``H264Encoder`` (ffmpeg as its own program), ``MJPEGEncoder`` and ``JpegEncoder``
(rollcam's JPEG encoder), and ``Encoder`` itself, which passes raw frames on; ``Quality``."""

from .encoder import Encoder, Quality
from .h264_encoder import H264Encoder, LibavH264Encoder
from .jpeg_encoder import JpegEncoder, LibavMjpegEncoder, MJPEGEncoder

__all__ = ["Encoder", "H264Encoder", "JpegEncoder", "LibavH264Encoder", "LibavMjpegEncoder", "MJPEGEncoder",
           "Quality"]
