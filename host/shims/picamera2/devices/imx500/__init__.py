"""The IMX500 helper (``IMX500``, ``NetworkIntrinsics``) and picamera2's post-processing functions, on
rollcam's emulated IMX500 (docs/picamera2.md)."""

from .imx500 import IMX500, NetworkIntrinsics
from .postprocess_efficientdet_lite0 import postprocess_efficientdet_lite0_detection
from .postprocess_nanodet import postprocess_nanodet_detection
from .postprocess_yolov5 import postprocess_yolov5_detection
from .postprocess_yolov8 import postprocess_yolov8_detection

__all__ = ["IMX500", "NetworkIntrinsics", "postprocess_efficientdet_lite0_detection",
           "postprocess_nanodet_detection", "postprocess_yolov5_detection", "postprocess_yolov8_detection"]
