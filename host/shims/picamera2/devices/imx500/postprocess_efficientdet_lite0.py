"""picamera2's host-side decoder of the efficientdet_lite0 network's raw head: not emulated (the emulated IMX500's
networks are post-processed on chip, ``_pp``: their outputs are boxes, scores and classes already)."""

from __future__ import annotations

from typing import Any


def postprocess_efficientdet_lite0_detection(*args: Any, **kwargs: Any) -> Any:
    """Not emulated: RuntimeError saying so (use a ``_pp`` network, whose outputs need no decoding)."""
    raise RuntimeError("rollcam's IMX500 runs post-processed (_pp) networks only; "
                       "postprocess_efficientdet_lite0_detection decodes a raw efficientdet_lite0 head, which the "
                       "emulated sensor does not send")
