"""Host detectors as in-sensor networks: the loader the firmware's in-sensor stage calls, and their op counts.

``rollcam.firmware.insensor`` knows networks only through its ``Network`` protocol; ``import rollcam.host``
registers ``load_network`` here, which builds any rollcam detector spec (``load_detector``) and wraps it as a
``HostNetwork``. Its ``macs`` (multiply-accumulates per run, which set the modelled latency and energy) are counted
from the ONNX graph at the model's input size (Conv, ConvTranspose, Gemm, MatMul), times the runs of one image
(tiles); HOG has no graph, and is costed at ``HOG_MACS_PER_PIXEL`` (a rough figure for gradients, cell histograms
and the linear SVM, stated as such in docs/insensor.md). A raw network gets the mosaic at the bit depth its model
was trained on.
"""

from __future__ import annotations

import functools
import threading
from pathlib import Path
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.firmware.insensor import NetworkOutput

HOG_MACS_PER_PIXEL = 200
"""Assumed cost of OpenCV's HOG people detector per input pixel and pyramid level (not measured)."""


@functools.lru_cache(maxsize=16)
def onnx_macs(path: str, width: int, height: int) -> int:
    """Multiply-accumulates of one run of the ONNX model at ``path`` on a ``width`` x ``height`` input (batch 1),
    from its graph's Conv, ConvTranspose, Gemm and MatMul nodes after shape inference."""
    from rollcam.common.errors import require

    onnx = require("onnx", feature="counting an in-sensor network's operations")
    model = onnx.load(path)
    dims = model.graph.input[0].type.tensor_type.shape.dim
    if len(dims) == 4:
        nchw = dims[1].dim_value in (1, 3)
        sizes = (1, dims[1].dim_value, height, width) if nchw else (1, height, width, dims[3].dim_value)
        for d, v in zip(dims, sizes, strict=True):
            d.ClearField("dim_param")
            d.dim_value = v
    model = onnx.shape_inference.infer_shapes(model)
    shapes: dict[str, list[int]] = {}
    for vi in [*model.graph.value_info, *model.graph.input, *model.graph.output]:
        shapes[vi.name] = [d.dim_value for d in vi.type.tensor_type.shape.dim]
    inits = {t.name: list(t.dims) for t in model.graph.initializer}
    shapes.update(inits)
    total = 0
    for node in model.graph.node:
        if node.op_type in ("Conv", "ConvTranspose"):
            w = shapes.get(node.input[1])
            out = shapes.get(node.output[0])
            if not w or not out:
                continue
            if node.op_type == "Conv":  # weight (Cout, Cin/g, kh, kw): each output element is Cin/g*kh*kw MACs
                total += int(np.prod(out)) * int(np.prod(w[1:]))
            else:  # weight (Cin, Cout/g, kh, kw): each input element feeds Cout/g*kh*kw outputs
                inp = shapes.get(node.input[0]) or []
                total += int(np.prod(inp)) * int(np.prod(w[1:]))
        elif node.op_type in ("Gemm", "MatMul"):
            a, b = shapes.get(node.input[0]), shapes.get(node.input[1])
            if a and b:
                total += int(np.prod(a)) * int(b[-1])
    return total


class HostNetwork:
    """A rollcam detector behind the firmware's ``Network`` protocol (one inference at a time)."""

    def __init__(self, spec: str, detector: Any, macs_per_run: int | None) -> None:
        self.spec = spec
        self.detector = detector
        self.name = spec
        self.input = "raw" if detector.input == "raw" else "isp"
        self._macs = macs_per_run
        self._lock = threading.Lock()

    def __repr__(self) -> str:
        return f"HostNetwork({self.spec!r}, {self.input}, {self.detector!r})"

    def runs_per_image(self) -> int:
        """Network runs one image costs (a tiled detector runs the whole frame and each tile)."""
        tiles = getattr(self.detector, "tiles", None)
        return 1 if tiles is None else tiles[0] * tiles[1] + int(getattr(self.detector, "full", True))

    def macs(self, width: int, height: int) -> int:
        """Multiply-accumulates of one image of ``width`` x ``height`` (see the module docstring)."""
        if self._macs is None:  # HOG: per pixel, over the pyramid's levels (a geometric series of areas)
            scale = float(getattr(self.detector, "scale", 1.05))
            levels = 1.0 / (1.0 - 1.0 / (scale * scale))
            return round(width * height * HOG_MACS_PER_PIXEL * min(levels, 64.0))
        return self._macs * self.runs_per_image()

    def run(self, image: np.ndarray, bits: int) -> NetworkOutput:
        """One inference; a raw mosaic is brought to the bit depth the model was trained on."""
        det = self.detector
        if self.input == "raw":
            want = getattr(det, "bits", None) or bits
            if want != bits:
                image = (image >> (bits - want)) if bits > want else (image.astype(np.uint32) << (want - bits))
            image = image.astype(np.uint8 if want <= 8 else np.uint16, copy=False)
            if getattr(det, "bits", 0) is None:
                det.bits = want
        with self._lock:
            dets = det.detect(image)
            tensors = tuple(getattr(det, "last_outputs", ()) or ())
        return NetworkOutput(dets.boxes, dets.scores, dets.classes, tensors)

    def close(self) -> None:
        """Release the detector."""
        self.detector.close()


COLOURNET = "colournet"
"""The spec of ``ColourNet``."""
COLOURNET_CLASSES = 1000
COLOURNET_SEED = 500


class ColourNet:
    """A generated classifier, built in code (no trained weights, nothing downloaded): the picture's mean colour
    (global average pooling of the 8-bit RGB planes, scaled to 0..1) times a seeded 3 x 1000 matrix plus a seeded
    bias gives 1000 logits (ImageNet's class count). What it says is a fixed function of its input, which is what
    a test of a classification pipeline needs (picamera2's classification example on the emulated AI Camera); it
    recognises nothing. Output: the tensor ``logits``, shape (1000,), float32; no boxes."""

    name = COLOURNET
    input = "isp"

    def __init__(self) -> None:
        rng = np.random.default_rng(COLOURNET_SEED)
        self.weights = rng.standard_normal((3, COLOURNET_CLASSES)).astype(np.float32) * 4
        self.bias = rng.standard_normal(COLOURNET_CLASSES).astype(np.float32)

    def macs(self, width: int, height: int) -> int:
        """The pooling's adds (one a sample) and the 3 x 1000 matrix."""
        return width * height * 3 + 3 * COLOURNET_CLASSES

    def logits(self, image_bgr: np.ndarray) -> np.ndarray:
        """The 1000 logits of an 8-bit BGR picture."""
        mean_rgb = np.asarray(image_bgr, np.float64).reshape(-1, 3).mean(axis=0)[::-1] / 255.0
        return (mean_rgb.astype(np.float32) @ self.weights + self.bias).astype(np.float32)

    def run(self, image: np.ndarray, bits: int) -> NetworkOutput:
        """One inference: no detections, the logits as the output tensor."""
        empty = np.zeros((0,), np.float32)
        return NetworkOutput(empty.reshape(0, 4), empty, empty.astype(np.int32), (("logits", self.logits(image)),))


COLOURSEG = "colourseg"
"""The spec of ``ColourSeg``."""
COLOURSEG_CLASSES = 21
COLOURSEG_MIN_SATURATION = 64


class ColourSeg:
    """A generated semantic segmentation network, built in code (no trained weights): a pixel whose saturation
    (HSV, 0..255) is below 64 is class 0 (background), any other one of 20 hue bins (classes 1..20; 21 classes, as
    Pascal VOC's DeepLabv3+ on the AI Camera). It segments coloured things from grey ones, not objects; what it
    says is a fixed function of its input. Output: the tensor ``mask``, shape (height, width) of the input, class
    ids as float32; no boxes."""

    name = COLOURSEG
    input = "isp"

    def macs(self, width: int, height: int) -> int:
        """The colour conversion and the binning, counted as 3 per pixel."""
        return width * height * 3

    def mask(self, image_bgr: np.ndarray) -> np.ndarray:
        """The class of every pixel of an 8-bit BGR picture, (H, W) float32."""
        from rollcam.sim.codecs import bgr_to_hsv

        hsv = bgr_to_hsv(image_bgr)
        bins = 1 + hsv[:, :, 0].astype(np.int32) * (COLOURSEG_CLASSES - 1) // 180
        return np.where(hsv[:, :, 1] < COLOURSEG_MIN_SATURATION, 0, bins).astype(np.float32)

    def run(self, image: np.ndarray, bits: int) -> NetworkOutput:
        """One inference: no detections, the mask as the output tensor."""
        empty = np.zeros((0,), np.float32)
        return NetworkOutput(empty.reshape(0, 4), empty, empty.astype(np.int32), (("mask", self.mask(image)),))


POSENET = "posenet"
"""The spec of ``PoseNet``."""
POSE_TEMPLATE = np.array([  # COCO's 17 keypoints as fractions (x, y) of a standing person's box
    (0.50, 0.07), (0.55, 0.05), (0.45, 0.05), (0.60, 0.07), (0.40, 0.07),  # nose, eyes, ears
    (0.70, 0.20), (0.30, 0.20), (0.78, 0.36), (0.22, 0.36), (0.80, 0.50), (0.20, 0.50),  # shoulders, elbows, wrists
    (0.62, 0.52), (0.38, 0.52), (0.60, 0.74), (0.40, 0.74), (0.60, 0.95), (0.40, 0.95),  # hips, knees, ankles
], np.float64)
POSE_PEOPLE = 30
POSE_STRIDE = 2


class PoseNet:
    """A generated pose network (no trained weights of its own): rollcam's ``personnet`` finds the people in the
    picture and COCO's 17 keypoints are placed in each box by a fixed standing-person template (``POSE_TEMPLATE``),
    each scored with the detection's score. Its outputs are HigherHRNet's with the top-k grouping done on chip (as
    the AI Camera's ``imx500_higherhrnet_coco`` sends them): ``tag_k``, ``ind_k`` and ``val_k``, each (30, 17) for up
    to 30 people: the person's tag (its rank + 1), the keypoint's index on the output grid (half the input's size:
    ``y * (W / 2) + x``) and its score (0: no person in that slot). It knows where people are, not how they stand."""

    name = POSENET
    input = "isp"

    def __init__(self) -> None:
        self.detector = load_network("personnet")

    def macs(self, width: int, height: int) -> int:
        """The person detector's, at this input (the template costs nothing to speak of)."""
        return self.detector.macs(width, height)

    def run(self, image: np.ndarray, bits: int) -> NetworkOutput:
        """One inference: the people found, and their keypoints in the post-processed layout."""
        found = self.detector.run(image, bits)
        boxes = np.asarray(found.boxes, np.float64).reshape(-1, 4)
        scores = np.asarray(found.scores, np.float32)
        order = np.argsort(-scores, kind="stable")[:POSE_PEOPLE]
        gw, gh = image.shape[1] // POSE_STRIDE, image.shape[0] // POSE_STRIDE
        tag = np.zeros((POSE_PEOPLE, 17), np.float32)
        ind = np.zeros((POSE_PEOPLE, 17), np.float32)
        val = np.zeros((POSE_PEOPLE, 17), np.float32)
        for slot, i in enumerate(order):
            x0, y0, x1, y1 = boxes[i]
            x = np.clip(np.floor((x0 + POSE_TEMPLATE[:, 0] * (x1 - x0)) / POSE_STRIDE), 0, gw - 1)
            y = np.clip(np.floor((y0 + POSE_TEMPLATE[:, 1] * (y1 - y0)) / POSE_STRIDE), 0, gh - 1)
            tag[slot], ind[slot], val[slot] = slot + 1, y * gw + x, scores[i]
        return NetworkOutput(boxes[order], scores[order], np.zeros(len(order), np.int32),
                             (("tag_k", tag), ("ind_k", ind), ("val_k", val)))


def load_network(spec: str) -> HostNetwork | ColourNet | ColourSeg | PoseNet:
    """The in-sensor network of a detector spec, or ``colournet``, ``colourseg`` or ``posenet`` (the loader
    ``rollcam.host`` registers with the firmware)."""
    from . import load_detector

    if spec == COLOURNET:
        return ColourNet()
    if spec == COLOURSEG:
        return ColourSeg()
    if spec == POSENET:
        return PoseNet()

    det = load_detector(spec)
    path = getattr(det, "path", None)
    if path is None:
        if getattr(det, "name", "") != "hog":
            raise ConfigError(f"insensor={spec!r}: the in-sensor stage needs a network it can cost: an ONNX model "
                              "(onnx:, personnet, personnet-raw, ssdlite) or hog")
        return HostNetwork(spec, det, None)
    return HostNetwork(spec, det, model_macs(Path(path), det.width, det.height))


def model_macs(path: Path, width: int, height: int) -> int:
    """MACs of one run of an ONNX model, counted from its graph."""
    return onnx_macs(str(path), width, height)
