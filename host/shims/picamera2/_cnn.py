"""The IMX500's network on the emulated camera: what ``IMX500(network_file)`` programs, and the request
metadata it yields (``CnnOutputTensor``, ``CnnOutputTensorInfo``, ``CnnKpiInfo``), laid out as libcamera's
Raspberry Pi IMX500 helper gives them to picamera2.

``CnnProgram`` is one camera's network: the in-sensor options of ``rollcam.firmware`` it sets
(``insensor=SPEC``, ``insensor_size`` = the network's input tensor), and the layout of a post-processed
("_pp") detection network's outputs: four tensors, boxes ``(slots, 4)``, scores ``(slots,)``, classes
``(slots,)`` and the count ``(1,)``, float32, each flattened in column-major order (a classifier's program
sends its network's own output tensors instead: ``colournet``'s 1000 logits; a segmenter's, ``colourseg``'s
class of every input pixel) (picamera2's
``get_outputs`` reshapes with ``order='F'``). Boxes are normalised to the sensor's full pixel array (what
``IMX500.convert_inference_coords`` takes), in ``yx`` (y0, x0, y1, x1) or ``xy`` order, and, for a network
whose boxes are in input-tensor pixels (``bbox_normalization``), times the input size. Unused slots are zero.

The tensors of a request are those of the newest in-sensor result the frame carries (``Frame.insensor``: the
results done since the previous frame, so usually the frame before's); ``CnnOutputTensorInfo.frameCount`` is
that result's source frame sequence number modulo 256, and ``RollcamInsensor`` lists every carried result in
full (``InSensorResult.to_json``: device-clock ns, boxes in the raw frame's pixels). A frame that carries none
has no ``Cnn*`` keys, as when a Pi's network runs slower than the frame rate. A network with an input tensor
(data injection) also gives ``CnnInputTensor``: the tensor it ran on, 3 x H x W unsigned bytes without padding.
"""

from __future__ import annotations

import struct
import threading
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

NETWORK_NAME_LEN = 64
MAX_NUM_TENSORS = 16
MAX_NUM_DIMENSIONS = 16
TENSOR_INFO = struct.Struct(f"<{NETWORK_NAME_LEN}sI" + f"II{MAX_NUM_DIMENSIONS}H" * MAX_NUM_TENSORS + "B3x")
"""libcamera's ``CnnOutputTensorInfoExported``: network name, tensor count, per tensor (elements, dimensions,
16 uint16 sizes), the frame count, padded to 4-byte alignment (712 bytes)."""
DEFAULT_SLOTS = 100
"""Detections a post-processed network reports per frame (the rest are dropped, lowest score first)."""


@dataclass(frozen=True)
class CnnProgram:
    """One camera's network: its name (the ``.rpk`` file's stem), the rollcam detector spec it runs, the
    input tensor size, the output layout, and the inference region in pixel-array coordinates (None: all)."""

    name: str
    network: str
    input_size: tuple[int, int] = (640, 640)
    bbox_normalization: bool = False
    bbox_order: str = "yx"
    slots: int = DEFAULT_SLOTS
    roi: tuple[int, int, int, int] | None = None
    tensor: str = "none"
    """The ``insensor_tensor`` option: the network's input tensor (set for data injection)."""
    task: str = "object detection"
    """``object detection``: the post-processed four tensors; any other task (``classification``,
    ``segmentation``): the network's own output tensors."""

    def options(self) -> dict[str, str]:
        """The in-sensor options of ``rollcam.firmware`` that run this network."""
        w, h = self.input_size
        options = {"insensor": self.network, "insensor_size": f"{w}x{h}", "insensor_tensor": self.tensor}
        if self.tensor != "none":
            options["insensor_input"] = "isp"
        return options


_PROGRAMS: dict[int, CnnProgram] = {}
_LOCK = threading.Lock()


def load(num: int, program: CnnProgram) -> None:
    """Program camera ``num``'s network (an open camera takes it at once, the next opened one on opening)."""
    from .picamera2 import _OPEN, _OPEN_LOCK

    with _LOCK:
        _PROGRAMS[num] = program
    with _OPEN_LOCK:
        cam = _OPEN.get(num)
    if cam is not None and cam._cam is not None:
        cam._cam.set_network(program)


def inject(num: int, tensor: bytes) -> int:
    """Inject an input tensor into open camera ``num``'s network; returns the comparison frame's sequence
    number (``InjectionBusy`` while an earlier tensor waits; RuntimeError when the camera is not open)."""
    from .picamera2 import _OPEN, _OPEN_LOCK

    with _OPEN_LOCK:
        cam = _OPEN.get(num)
    if cam is None or cam._cam is None:
        raise RuntimeError(f"IMX500: camera {num} is not open: open it with Picamera2 before injecting a tensor")
    return cam._cam.inject(tensor)


def set_roi(num: int, roi: tuple[int, int, int, int] | None) -> None:
    """Change camera ``num``'s inference region (pixel-array coordinates; None: the whole array)."""
    with _LOCK:
        current = _PROGRAMS.get(num)
    if current is not None:
        load(num, replace(current, roi=roi))


def program_of(num: int) -> CnnProgram | None:
    """Camera ``num``'s network, if ``IMX500`` programmed one."""
    with _LOCK:
        return _PROGRAMS.get(num)


def unload_all() -> None:
    """Forget every programmed network (the pytest fixture does, with the cameras)."""
    with _LOCK:
        _PROGRAMS.clear()


def roi_option(program: CnnProgram, array_crop: tuple[int, int, int, int], size: tuple[int, int]) -> str:
    """``insensor_roi`` for the mode reading ``array_crop`` of the pixel array into a ``size`` image."""
    if program.roi is None:
        return "none"
    cx, cy, cw, ch = array_crop
    w, h = size
    x0 = max(round((program.roi[0] - cx) * w / cw), 0)
    y0 = max(round((program.roi[1] - cy) * h / ch), 0)
    x1 = min(round((program.roi[0] + program.roi[2] - cx) * w / cw), w)
    y1 = min(round((program.roi[1] + program.roi[3] - cy) * h / ch), h)
    return f"{x0},{y0},{max(x1 - x0, 2)},{max(y1 - y0, 2)}"


def tensor_info(name: str, shapes: list[tuple[int, ...]], frame_count: int) -> bytes:
    """The packed ``CnnOutputTensorInfoExported`` of tensors of ``shapes``."""
    fields: list[Any] = [name.encode("utf-8")[: NETWORK_NAME_LEN - 1], len(shapes)]
    for i in range(MAX_NUM_TENSORS):
        shape = tuple(shapes[i]) if i < len(shapes) else ()
        dims = [*shape, *[0] * (MAX_NUM_DIMENSIONS - len(shape))]
        fields.extend([int(np.prod(shape)) if shape else 0, len(shape), *dims])
    fields.append(frame_count & 0xFF)
    return TENSOR_INFO.pack(*fields)


def output_tensors(program: CnnProgram, result: Any, array_crop: tuple[int, int, int, int],
                   frame_size: tuple[int, int], array_size: tuple[int, int]) -> list[np.ndarray]:
    """A result's boxes, scores, classes and count as the post-processed network's four output tensors."""
    order = np.argsort(-result.scores, kind="stable")[: program.slots]
    n = len(order)
    boxes = np.zeros((program.slots, 4), np.float32)
    scores = np.zeros(program.slots, np.float32)
    classes = np.zeros(program.slots, np.float32)
    if n:
        b = result.boxes[order].astype(np.float64)
        cx, cy, cw, ch = array_crop
        fw, fh = frame_size
        aw, ah = array_size
        x = (cx + b[:, [0, 2]] * cw / fw) / aw
        y = (cy + b[:, [1, 3]] * ch / fh) / ah
        x, y = np.clip(x, 0, 1), np.clip(y, 0, 1)
        if program.bbox_normalization:  # the network gives input-tensor pixels
            x, y = x * program.input_size[0], y * program.input_size[1]
        cols = (y[:, 0], x[:, 0], y[:, 1], x[:, 1]) if program.bbox_order == "yx" else \
            (x[:, 0], y[:, 0], x[:, 1], y[:, 1])
        boxes[:n] = np.stack(cols, axis=1)
        scores[:n] = result.scores[order]
        classes[:n] = result.classes[order]
    return [boxes, scores, classes, np.array([n], np.float32)]


def cnn_metadata(program: CnnProgram, frame: Any, array_crop: tuple[int, int, int, int],
                 array_size: tuple[int, int]) -> dict[str, Any]:
    """The ``Cnn*`` keys (and ``RollcamInsensor``) of a frame's request; empty when it carries no result."""
    carried = tuple(getattr(frame, "insensor", ()) or ())
    if not carried:
        return {}
    result = carried[-1]
    if program.task == "object detection":
        tensors = output_tensors(program, result, array_crop, (frame.width, frame.height), array_size)
    else:  # the network's own output tensors, as the sensor sends a network without on-chip post-processing
        tensors = [np.asarray(t, np.float32) for _, t in result.tensors]
    flat = np.concatenate([t.ravel(order="F") for t in tensors])
    return {
        # A tuple, as libcamera's float span arrives (picamera2 tests it with `if not tensor`).
        "CnnOutputTensor": tuple(flat.tolist()),
        "CnnOutputTensorInfo": tensor_info(program.name, [t.shape for t in tensors], result.seq),
        "CnnKpiInfo": (-(-result.latency_ns // 1000), 0),  # DNN and DSP runtimes, us (no DSP stage modelled)
        "RollcamInsensor": [r.to_json() for r in carried],
        **({} if result.input_tensor is None else {"CnnInputTensor": input_tensor(program, result.input_tensor)}),
    }


def input_tensor(program: CnnProgram, tensor: np.ndarray) -> tuple[int, ...]:
    """``CnnInputTensor``: the tensor's planes without the DSP's padding, as unsigned bytes (3 x H x W)."""
    from rollcam.firmware.input_tensor import parse_tensor_format

    fmt = parse_tensor_format(program.tensor)
    assert fmt is not None
    return tuple(fmt.planes(tensor).ravel().tolist())
