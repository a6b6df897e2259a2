"""picamera2's device helpers on rollcam: the IMX500 (the Raspberry Pi AI Camera). Hailo and the IMX708's
HDR helper are not emulated (importing them fails, as on a Pi without them)."""

from .imx500 import IMX500

__all__ = ["IMX500"]
