"""Which rollcam network an IMX500 "network firmware" file runs on the emulated camera (rollcam's extra).

A Pi script names a network as an ``.rpk`` file of Sony's model zoo
(``/usr/share/imx500-models/imx500_network_ssd_mobilenetv2_fpnlite_320x320_pp.rpk``). The emulated IMX500 has
no firmware to load: the file's name (its stem; the file need not exist) picks a row of ``ZOO``, a rollcam
detector the in-sensor stage runs, its input tensor size (the accelerator's largest input) and the layout the
real network's post-processed outputs have (box order, boxes normalised or in input pixels). In place of an
``.rpk``, an ``.onnx`` file runs as ``onnx:PATH`` and any rollcam detector spec (``personnet-raw``,
``ssdlite?conf=0.2``) as itself, both with the ``_pp`` layout of the default row. With data injection
(``IMX500(..., tensor_injection=True)``) the network takes an input tensor, which the sensor's ISP makes from its
picture: a row then runs ``picture_detector`` (``personnet``) on the picture an RGB int8 tensor of its input size
shows. Rollcam's detectors find
people; their class 0 is COCO's "person".
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from rollcam.host.detectors.onnx import COCO_NAMES

COCO_LABELS = COCO_NAMES
"""The 80 COCO class names, in the order detection networks number them (the ``onnx:`` detector's table)."""


@dataclass(frozen=True)
class ZooNetwork:
    """One model-zoo network as the emulated IMX500 runs it."""

    stem: str
    detector: str
    input_size: tuple[int, int]
    bbox_normalization: bool = False
    bbox_order: str = "yx"
    picture_detector: str = "personnet"
    """What runs with data injection: the input tensor is the ISP's picture, so the picture-trained twin."""
    task: str = "object detection"
    """``object detection`` (post-processed boxes, scores, classes, count), ``classification`` (the logits),
    ``segmentation`` (the class of every input pixel) or ``pose estimation`` (HigherHRNet's grouped keypoints)."""

    def tensor(self) -> str:
        """The network's input tensor (``insensor_tensor``): RGB, int8, centred (picamera2's default norm)."""
        w, h = self.input_size
        return f"{w}x{h},rgb,int8"


ZOO = {z.stem: z for z in (
    ZooNetwork("imx500_network_ssd_mobilenetv2_fpnlite_320x320_pp", "personnet-raw", (320, 320)),
    ZooNetwork("imx500_network_efficientdet_lite0_pp", "personnet-raw", (320, 320)),
    ZooNetwork("imx500_network_nanodet_plus_416x416_pp", "personnet-raw", (416, 416)),
    ZooNetwork("imx500_network_yolov8n_pp", "personnet-raw", (640, 640), bbox_normalization=True, bbox_order="xy"),
    ZooNetwork("imx500_network_yolo11n_pp", "personnet-raw", (640, 640), bbox_normalization=True, bbox_order="xy"),
    ZooNetwork("imx500_network_mobilenet_v2", "colournet", (224, 224), picture_detector="colournet",
               task="classification"),
    ZooNetwork("imx500_network_deeplabv3plus", "colourseg", (513, 513), picture_detector="colourseg",
               task="segmentation"),
    ZooNetwork("imx500_network_higherhrnet_coco", "posenet", (384, 288), picture_detector="posenet",
               task="pose estimation"),
)}
"""Model-zoo object detectors (post-processed on chip) -> the rollcam detector run in their place: the
study's raw-trained ``personnet-raw`` (it reads the mosaic, as an in-sensor network does), within the named
network's input size, with that network's box layout (the yolo exports give input-tensor pixels, x first)."""
DEFAULT_INPUT = (640, 640)


def resolve(network_file: str) -> ZooNetwork:
    """The network a script's ``network_file`` names (see the module docstring); RuntimeError when it is an
    ``.rpk`` rollcam does not know."""
    text = os.fspath(network_file).strip()
    base = os.path.basename(text)
    stem, ext = os.path.splitext(base)
    if ext.lower() == ".rpk":
        if stem in ZOO:
            return ZOO[stem]
        raise RuntimeError(f"IMX500: network firmware {network_file!r} is not one rollcam emulates; known: "
                           f"{sorted(ZOO)} (or give an .onnx file or a rollcam detector spec)")
    if ext.lower() == ".onnx":
        if not os.path.isfile(text):
            raise RuntimeError(f"Firmware file {text} does not exist.")
        spec = f"onnx:{os.path.abspath(text)}"
        return ZooNetwork(stem, spec, DEFAULT_INPUT, picture_detector=spec)
    if not text:
        raise RuntimeError("IMX500: no network file given")
    return ZooNetwork(text.split("?", 1)[0], text, DEFAULT_INPUT, picture_detector=text)
