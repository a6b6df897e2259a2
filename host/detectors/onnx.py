"""``onnx:PATH``: any ONNX detection model through onnxruntime, YOLO-style or SSD-style outputs.

Output layouts (``layout=auto`` tells them apart by the model's outputs):

- ``yolo``: one tensor ``[1, 4+C, N]`` (YOLOv8/YOLO11 exports) or ``[1, N, 4+C]`` (channels are taken to be
  the shorter axis); cx, cy, w, h in input pixels, then C class scores.
- ``ssd``: ``boxes [1, N, 4]``, ``scores [1, N]``, ``classes [1, N]`` and optionally ``num_detections``,
  found by their names; boxes ``box=yxyx`` (TF, default) or ``xyxy``, normalised 0..1 or in input pixels
  (``norm`` 1/0; by default normalised when no coordinate exceeds 1.5).

Input: NCHW float (YOLO: RGB / 255, letterboxed with grey bars) or NHWC uint8 (TF SSD: RGB 0..255,
stretched), read from the model's input tensor. Options: ``conf`` (score threshold, 0.25), ``iou`` (NMS IoU,
0.45), ``classes`` (comma list of kept class ids, after ``class_offset``), ``class_offset`` (subtracted from
model class ids: 1 maps TF's 1-based labels onto COCO's 0-based ``person = 0``), ``size`` (WxH for models
with dynamic input size; 640x640 YOLO, 300x300 SSD), ``letterbox`` (1/0; default 1 for YOLO, 0 for SSD),
``bgr`` (1 feeds BGR instead of RGB), ``max_det`` (300), ``threads`` (onnxruntime intra-op threads),
``device`` (``cpu``, or ``cuda`` with onnxruntime-gpu installed), ``tiles`` (CxR: also run the model on
C x R overlapping tiles and merge, for small pedestrians in large frames), ``overlap`` (tile overlap
fraction, 0.2), ``full`` (1/0: with tiles, also run the whole frame; 1), ``merge`` (``ios``: before NMS, a
box removes the lower-scoring ones that lie inside it by at least ``merge_ios`` (0.5) of the smaller's area,
see ``ops.suppress_contained``; ``nms``: plain NMS over all tiles),
``input`` (``bgr`` or ``raw``: a raw model gets the sensor mosaic, scaled to 0..1 by ``bits``, the mosaic's
bit depth; default the full range of its dtype. Give raw models frames at their input size, or use tiles of
it: resizing a mosaic blends its colour sites). A model's metadata may set the defaults of ``input`` and
``bits`` (``rollcam_input``, ``rollcam_bits``, as ``rollcam train`` writes them) and its class names
(``names``, a dict literal as Ultralytics writes it).
"""

from __future__ import annotations

import ast
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

import numpy as np
from rollcam.common.errors import ConfigError, MissingDependencyError, require
from rollcam.common.values import fraction, parse_bool, parse_size, positive_int

from .base import Detections, DetectorSpec
from .ops import Placement, letterbox, nms, stretch, suppress_contained, tile_windows

OPTIONS = {"conf", "iou", "classes", "class_offset", "size", "letterbox", "bgr", "max_det", "threads", "tiles",
           "overlap", "full", "merge", "merge_ios", "layout", "box", "norm", "input", "bits", "device"}
LAYOUTS = ("auto", "yolo", "ssd")
SSD_ROLES = {"boxes": ("box",), "scores": ("score",), "classes": ("class", "label"), "num": ("num", "count")}
"""Role of each SSD output -> substrings its name contains (first match wins, case-insensitive)."""
DEFAULT_SIZE = {"yolo": (640, 640), "ssd": (300, 300)}

COCO_NAMES = (
    "person", "bicycle", "car", "motorcycle", "airplane", "bus", "train", "truck", "boat", "traffic light",
    "fire hydrant", "stop sign", "parking meter", "bench", "bird", "cat", "dog", "horse", "sheep", "cow",
    "elephant", "bear", "zebra", "giraffe", "backpack", "umbrella", "handbag", "tie", "suitcase", "frisbee",
    "skis", "snowboard", "sports ball", "kite", "baseball bat", "baseball glove", "skateboard", "surfboard",
    "tennis racket", "bottle", "wine glass", "cup", "fork", "knife", "spoon", "bowl", "banana", "apple",
    "sandwich", "orange", "broccoli", "carrot", "hot dog", "pizza", "donut", "cake", "chair", "couch",
    "potted plant", "bed", "dining table", "toilet", "tv", "laptop", "mouse", "remote", "keyboard", "cell phone",
    "microwave", "oven", "toaster", "sink", "refrigerator", "book", "clock", "vase", "scissors", "teddy bear",
    "hair drier", "toothbrush",
)
"""The 80 COCO class names in YOLO order (class id = index)."""


def import_onnxruntime() -> Any:
    """onnxruntime (an install dependency), or a MissingDependencyError saying the install is broken."""
    return require("onnxruntime", feature="the onnx detector")


def _overlap(text: str) -> float:
    value = float(text)
    if not 0.0 <= value < 1.0:
        raise ValueError("must be >= 0 and < 1")
    return value


def _int_list(text: str) -> tuple[int, ...]:
    return tuple(int(v) for v in text.split(",") if v.strip())


def _choice(*values: str) -> Callable[[str], str]:
    def parse(text: str) -> str:
        if text not in values:
            raise ValueError(f"must be one of {list(values)}")
        return text
    return parse


def fit_image(image: np.ndarray, width: int, height: int, *, input: str = "bgr", letterbox_input: bool = True,
              bgr: bool = False, channels: int = 3) -> tuple[np.ndarray, Placement]:
    """An image fitted to a ``width`` x ``height`` network input, H x W x C in its own scale, with its placement.

    A raw mosaic stays one channel in its own dtype; a picture (BGR, grey or BGRA) becomes RGB (BGR with
    ``bgr``), or its channel mean for a one-channel model. ``rollcam train`` fits its images with this same
    function, so a model sees in training exactly what this detector feeds it.
    """
    img = np.asarray(image)
    if input == "raw":
        if img.ndim == 3 and img.shape[2] != 1:
            raise ConfigError(f"a raw-input model (input=raw) takes the sensor's one-channel mosaic, not a "
                              f"{img.shape[1]}x{img.shape[0]} picture of {img.shape[2]} channels: give it raw frames "
                              "(an emu: source with format=, a dataset made with --raw)")
        fitted, place = (letterbox if letterbox_input else stretch)(img, width, height)
        return (fitted[..., None] if fitted.ndim == 2 else fitted), place
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    elif img.shape[2] == 4:
        img = img[..., :3]
    fitted, place = (letterbox if letterbox_input else stretch)(img, width, height)
    if not bgr:
        fitted = fitted[..., ::-1]
    if channels == 1:
        fitted = fitted.mean(axis=2, keepdims=True)
    return fitted, place


def input_scale(dtype: np.dtype, input: str = "bgr", bits: int | None = None) -> float:
    """The factor that maps fitted samples to the 0..1 a float model takes: 1/255 for pictures; for a raw mosaic
    one over its full scale (``bits`` wide, by default the whole range of its dtype)."""
    if input != "raw":
        return 1 / 255
    dt = np.dtype(dtype)
    return 1.0 / ((1 << bits) - 1 if bits else (np.iinfo(dt).max if dt.kind in "ui" else 1.0))


class OnnxDetector:
    """A detection model run by onnxruntime, with its pre- and post-processing chosen from its tensors."""

    def __init__(self, path: str | Path, *, conf: float = 0.25, iou: float = 0.45,
                 classes: tuple[int, ...] | None = None, class_offset: int = 0, size: tuple[int, int] | None = None,
                 letterbox_input: bool | None = None, bgr: bool = False, max_det: int = 300,
                 threads: int | None = None, tiles: tuple[int, int] | None = None,
                 overlap: float = 0.2, full: bool = True, merge: str = "ios", merge_ios: float = 0.5,
                 layout: str = "auto", box: str = "yxyx",
                 norm: bool | None = None, input: Literal["bgr", "raw"] | None = None, bits: int | None = None,
                 device: str = "cpu", name: str = "onnx", class_names: dict[int, str] | None = None) -> None:
        ort = import_onnxruntime()
        self.path = Path(path)
        if not self.path.is_file():
            raise ConfigError(f"ONNX model {str(self.path)!r} does not exist")
        opts = ort.SessionOptions()
        if threads:
            opts.intra_op_num_threads = threads
        providers = ["CPUExecutionProvider"]
        if device == "cuda":
            if "CUDAExecutionProvider" not in ort.get_available_providers():
                raise MissingDependencyError("onnxruntime-gpu", feature=f"detector {name!r}: device=cuda (this "
                                             f"onnxruntime offers {ort.get_available_providers()})")
            providers.insert(0, "CUDAExecutionProvider")
        try:
            self._session = ort.InferenceSession(str(self.path), opts, providers=providers)
        except Exception as exc:  # onnxruntime raises its own untyped errors for unreadable models
            raise ConfigError(f"ONNX model {str(self.path)!r} cannot be loaded: {exc}") from None
        meta = self._session.get_modelmeta().custom_metadata_map
        # A model may say what it takes (rollcam train writes these): the spec's own options still win.
        input = input or meta.get("rollcam_input", "bgr")
        if input not in ("bgr", "raw"):
            raise ConfigError(f"ONNX model {str(self.path)!r}: metadata rollcam_input={input!r} is not bgr or raw")
        if bits is None and meta.get("rollcam_bits", "").isdigit():
            bits = int(meta["rollcam_bits"])
        self.name, self.input, self.bits = name, input, bits
        self.conf, self.iou, self.max_det = conf, iou, max_det
        self.keep_classes = None if classes is None else np.asarray(classes, np.int32)
        self.class_offset, self.bgr, self.box, self.norm = class_offset, bgr, box, norm
        self.tiles, self.overlap, self.full = tiles, overlap, full
        self.merge, self.merge_ios = merge, merge_ios
        self.layout = self._find_layout(layout)
        inp = self._session.get_inputs()[0]
        self._input_name = inp.name
        self._uint8 = "uint8" in inp.type
        shape = list(inp.shape)
        self._nchw = len(shape) == 4 and shape[1] in (1, 3)
        self._channels = shape[1] if self._nchw else (shape[3] if len(shape) == 4 else 3)
        hw = shape[2:4] if self._nchw else shape[1:3]
        fixed = tuple(hw) if all(isinstance(v, int) and v > 0 for v in hw) else None
        if size is not None and fixed is not None and (size[1], size[0]) != fixed:
            raise ConfigError(f"detector {name!r}: size={size[0]}x{size[1]} but the model's input is fixed at "
                              f"{fixed[1]}x{fixed[0]}")
        self.width, self.height = size or ((fixed[1], fixed[0]) if fixed else DEFAULT_SIZE[self.layout])
        self.letterbox = (self.layout == "yolo") if letterbox_input is None else letterbox_input
        self.class_names = class_names or self._names_from_metadata()
        self.last_outputs: tuple[tuple[str, np.ndarray], ...] = ()  # the raw output tensors of the last run

    # ------------------------------------------------------------------------------------------ model layout
    def _find_layout(self, layout: str) -> str:
        outputs = self._session.get_outputs()
        if layout == "auto":
            layout = "yolo" if len(outputs) == 1 else "ssd"
        if layout == "yolo":
            if len(outputs) != 1 or len(outputs[0].shape) != 3:
                raise ConfigError(f"ONNX model {str(self.path)!r}: layout yolo needs one [1, 4+C, N] output, has "
                                  f"{[(o.name, o.shape) for o in outputs]}")
            return layout
        roles: dict[str, str] = {}
        for role, keys in SSD_ROLES.items():
            for o in outputs:
                if o.name not in roles.values() and any(k in o.name.lower() for k in keys):
                    roles[role] = o.name
                    break
        missing = [r for r in ("boxes", "scores", "classes") if r not in roles]
        if missing:
            raise ConfigError(f"ONNX model {str(self.path)!r}: SSD layout needs outputs named like boxes, scores "
                              f"and classes; none matches {missing} among {[o.name for o in outputs]}")
        self._ssd_outputs = roles
        return layout

    def _names_from_metadata(self) -> dict[int, str]:
        meta = self._session.get_modelmeta().custom_metadata_map
        if "names" in meta:  # Ultralytics exports store their class names as a Python dict literal
            try:
                names = ast.literal_eval(meta["names"])
                return {int(k): str(v) for k, v in names.items()}
            except (ValueError, SyntaxError, AttributeError):
                pass
        return dict(enumerate(COCO_NAMES))

    # ------------------------------------------------------------------------------------------ inference
    def _prepare(self, image: np.ndarray) -> tuple[np.ndarray, Placement]:
        fitted, place = fit_image(image, self.width, self.height, input=self.input, letterbox_input=self.letterbox,
                                  bgr=self.bgr, channels=self._channels)
        scale = np.float32(input_scale(fitted.dtype, self.input, self.bits))
        if self._uint8:
            arr = fitted.astype(np.uint8) if self.input != "raw" else \
                np.clip(fitted.astype(np.float32) * scale * 255, 0, 255).astype(np.uint8)
            arr = arr.transpose(2, 0, 1) if self._nchw else arr
            return np.ascontiguousarray(arr[None]), place
        if fitted.dtype.kind == "f" and fitted.dtype != np.float32:
            fitted = fitted.astype(np.float32)
        # Cast, scale and transpose in one pass into the tensor: a fifth of the time of the three passes apart
        # (0.43 against 2.5 ms for a 640x360 picture), with the same float32 products.
        src = fitted.transpose(2, 0, 1) if self._nchw else fitted
        tensor = np.empty((1, *src.shape), np.float32)
        np.multiply(src, scale, out=tensor[0])
        return tensor, place

    def _infer(self, names: list[str], tensor: np.ndarray) -> list[np.ndarray]:
        """The model's outputs ``names`` for ``tensor``; a model that loads but cannot run (a bad reshape, an input
        it does not take) is one ConfigError naming the model and the input, as one that cannot load is."""
        try:
            return [np.asarray(o) for o in self._session.run(names, {self._input_name: tensor})]
        except Exception as exc:  # onnxruntime raises its own untyped errors (Fail, InvalidArgument, ...)
            why = " ".join(str(exc).split())[:300]
            raise ConfigError(f"ONNX model {str(self.path)!r} failed on a {list(tensor.shape)} {tensor.dtype} "
                              f"input: {why}") from None

    def _decode(self, outs: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Boxes, scores and classes from the outputs in the model's layout (a ConfigError if it cannot hold them)."""
        try:
            return self._decode_yolo(outs[0]) if self.layout == "yolo" else self._decode_ssd(outs)
        except (ValueError, IndexError, TypeError) as exc:
            raise ConfigError(f"ONNX model {str(self.path)!r}: outputs {[o.shape for o in outs]} do not fit the "
                              f"{self.layout} layout ({exc})") from None

    def _run(self, image: np.ndarray) -> Detections:
        tensor, place = self._prepare(image)
        # SSD: boxes, scores, classes and (when the model has it) num, in the order _find_layout found them
        names = [self._session.get_outputs()[0].name] if self.layout == "yolo" else [*self._ssd_outputs.values()]
        outs = self._infer(names, tensor)
        self.last_outputs = tuple(zip(names, outs, strict=True))
        boxes, scores, classes = self._decode(outs)
        classes = classes - self.class_offset
        keep = scores >= self.conf
        if self.keep_classes is not None:
            keep &= np.isin(classes, self.keep_classes)
        boxes = place.to_source(boxes[keep])
        h, w = image.shape[:2]
        boxes[:, [0, 2]] = boxes[:, [0, 2]].clip(0, w)
        boxes[:, [1, 3]] = boxes[:, [1, 3]].clip(0, h)
        return Detections(boxes, scores[keep], classes[keep])

    def _decode_yolo(self, out: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        pred = out[0]
        if pred.shape[0] > pred.shape[1]:  # [N, 4+C] exports: channels on the short axis
            pred = pred.T
        cx, cy, bw, bh = pred[:4]
        cls_scores = pred[4:]
        if not len(cls_scores):
            raise ConfigError(f"ONNX model {str(self.path)!r}: YOLO output {out.shape} has no class scores")
        classes = np.argmax(cls_scores, axis=0).astype(np.int32)
        scores = cls_scores[classes, np.arange(pred.shape[1])].astype(np.float32)
        boxes = np.stack([cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2], axis=1).astype(np.float32)
        return boxes, scores, classes

    def _decode_ssd(self, outs: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        boxes = np.asarray(outs[0], np.float32).reshape(-1, 4)
        scores = np.asarray(outs[1], np.float32).reshape(-1)
        classes = np.rint(np.asarray(outs[2])).astype(np.int32).reshape(-1)
        if len(outs) > 3:
            n = int(np.asarray(outs[3]).reshape(-1)[0])
            boxes, scores, classes = boxes[:n], scores[:n], classes[:n]
        if self.box == "yxyx":
            boxes = boxes[:, [1, 0, 3, 2]]
        normalised = self.norm if self.norm is not None else (not len(boxes) or float(np.abs(boxes).max()) <= 1.5)
        if normalised:
            boxes = boxes * np.array([self.width, self.height, self.width, self.height], np.float32)
        return boxes, scores, classes

    def detect(self, image: np.ndarray) -> Detections:
        """Detections on one image (BGR, or the raw mosaic for ``input=raw``), best first, after NMS."""
        img = np.asarray(image)
        if self.tiles is None:
            parts = [self._run(img)]
        else:
            h, w = img.shape[:2]
            parts = [self._run(img)] if self.full else []
            for x0, y0, x1, y1 in tile_windows(w, h, *self.tiles, self.overlap):
                d = self._run(img[y0:y1, x0:x1])
                parts.append(Detections(d.boxes + np.array([x0, y0, x0, y0], np.float32), d.scores, d.classes))
        boxes = np.concatenate([p.boxes for p in parts])
        scores = np.concatenate([p.scores for p in parts])
        classes = np.concatenate([p.classes for p in parts])
        if self.tiles is not None and self.merge == "ios":
            inside = suppress_contained(boxes, scores, classes, self.merge_ios)
            boxes, scores, classes = boxes[inside], scores[inside], classes[inside]
        keep = nms(boxes, scores, classes, self.iou, self.max_det)
        return Detections(boxes[keep], scores[keep], classes[keep])

    def close(self) -> None:
        """Drop the onnxruntime session; safe to call twice."""
        self._session = None

    def __repr__(self) -> str:
        tiles = "" if self.tiles is None else f", tiles={self.tiles[0]}x{self.tiles[1]}"
        return f"OnnxDetector({self.path.name!r}, {self.layout}, {self.width}x{self.height}, conf={self.conf}{tiles})"


def detector_options(spec: DetectorSpec) -> dict[str, Any]:
    """Keyword arguments of ``OnnxDetector`` from a spec's options (shared with ``ssdlite``)."""
    spec.check(OPTIONS)
    kw: dict[str, Any] = {
        "conf": spec.get("conf", fraction, 0.25), "iou": spec.get("iou", fraction, 0.45),
        "classes": spec.get("classes", _int_list), "class_offset": spec.get("class_offset", int, 0),
        "size": spec.get("size", parse_size), "letterbox_input": spec.get("letterbox", parse_bool),
        "bgr": spec.get("bgr", parse_bool, False), "max_det": spec.get("max_det", positive_int, 300),
        "threads": spec.get("threads", positive_int), "tiles": spec.get("tiles", parse_size),
        "overlap": spec.get("overlap", _overlap, 0.2), "full": spec.get("full", parse_bool, True),
        "merge": spec.get("merge", _choice("ios", "nms"), "ios"), "merge_ios": spec.get("merge_ios", fraction, 0.5),
        "layout": spec.get("layout", _choice(*LAYOUTS), "auto"),
        "box": spec.get("box", _choice("yxyx", "xyxy"), "yxyx"),
        "norm": spec.get("norm", parse_bool), "input": spec.get("input", _choice("bgr", "raw")),
        "bits": spec.get("bits", positive_int), "device": spec.get("device", _choice("cpu", "cuda"), "cpu"),
    }
    return kw


def open_detector(spec: DetectorSpec) -> OnnxDetector:
    """Build an ONNX detector from ``onnx:PATH?conf=..&iou=..&classes=..&tiles=..``."""
    kw = detector_options(spec)
    if not spec.target:
        raise ConfigError(f"detector {spec.spec!r}: name a model file, e.g. onnx:yolo11n.onnx")
    return OnnxDetector(spec.target, **kw)
