"""``IMX500``: picamera2's helper for the Raspberry Pi AI Camera, on rollcam's emulated IMX500.

On a Pi, ``IMX500(network_file)`` uploads a network to the sensor before ``Picamera2`` opens it, and each
request's metadata then carries the network's output tensors, which the helper reshapes
(``get_outputs``) and maps into an output stream's pixels (``convert_inference_coords``). Here the network
file names a rollcam network (``networks.py``) that the emulated camera's in-sensor stage runs on each frame
it has time for, on the device clock (``rollcam.firmware.insensor_stage``); the tensors reach the request
metadata in libcamera's layout (``picamera2._cnn``). The camera is the first emulated one whose sensor is an
``imx500`` (``ROLLCAM_PICAMERA2=imx500``), or the one whose id contains ``camera_id``. What is covered:
docs/picamera2.md.
"""

from __future__ import annotations

import errno
import hashlib
import os
from typing import Any

import numpy as np
from rollcam.firmware.input_tensor import parse_tensor_format
from rollcam.firmware.insensor_stage import InjectionBusy

from ... import _cnn
from ..._camera import sources, spec_of
from ._intrinsics import NetworkIntrinsics
from .networks import COCO_LABELS, resolve

__all__ = ["IMX500", "NetworkIntrinsics"]

Rect = tuple[int, int, int, int]


def _scaled(r: Rect, num: tuple[int, int], den: tuple[int, int]) -> Rect:
    """libcamera's ``Rectangle.scaled_by``: every coordinate times num / den (integer division)."""
    x, y, w, h = r
    return (x * num[0] // den[0], y * num[1] // den[1], w * num[0] // den[0], h * num[1] // den[1])


def _bounded(r: Rect, bound: Rect) -> Rect:
    """libcamera's ``Rectangle.boundedTo``: the part of ``r`` inside ``bound`` (empty: zero size)."""
    x0, y0 = max(r[0], bound[0]), max(r[1], bound[1])
    x1, y1 = min(r[0] + r[2], bound[0] + bound[2]), min(r[1] + r[3], bound[1] + bound[3])
    return (x0, y0, max(x1 - x0, 0), max(y1 - y0, 0))


class IMX500:
    """The emulated IMX500 and the network it runs (see the module docstring)."""

    def __init__(self, network_file: str, camera_id: str = "", tensor_injection: bool = False) -> None:
        self.__num, self.__sensor = self.__find_camera(camera_id)
        zoo = resolve(network_file)
        self.__injection = bool(tensor_injection)
        self.__cmp_frm = 0
        # A classifier reads the input tensor always (a picture network); a detector only with injection.
        tensor = zoo.tensor() if tensor_injection or zoo.task != "object detection" else "none"
        self.__program = _cnn.CnnProgram(zoo.stem, zoo.picture_detector if tensor != "none" else zoo.detector,
                                         zoo.input_size, zoo.bbox_normalization, zoo.bbox_order, tensor=tensor,
                                         task=zoo.task)
        if zoo.task == "object detection":
            intrinsics = NetworkIntrinsics({"task": zoo.task, "inference_rate": 30.0,
                                            "cpu": {"bbox_normalization": zoo.bbox_normalization,
                                                    "bbox_order": zoo.bbox_order},
                                            "classes": {"labels": list(COCO_LABELS)}})
        else:  # the script brings its labels (picamera2's examples read their assets' ImageNet list)
            intrinsics = NetworkIntrinsics({"task": zoo.task, "inference_rate": 30.0})
        w, h = zoo.input_size
        self.__cfg: dict[str, Any] = {"network_file": network_file, "intrinsics": intrinsics,
                                      "input_tensor": {"width": w, "height": h, "input_format": "RGB"},
                                      "input_tensor_size": (w, h), "rollcam_network": self.__program.network}
        fmt = parse_tensor_format(zoo.tensor())
        assert fmt is not None
        self.__cfg["input_tensor"].update({"norm_val": list(fmt.norm_val), "norm_shift": list(fmt.norm_shift),
                                           "div_val": list(fmt.div_val), "div_shift": fmt.div_shift})
        _cnn.load(self.__num, self.__program)
        self.set_inference_roi_abs(self.__full())

    @staticmethod
    def __find_camera(camera_id: str) -> tuple[int, Any]:
        for num, source in enumerate(sources()):
            sensor = spec_of(source).sensor
            cam_id = f"/base/soc/i2c0mux/i2c@{num}/{sensor.name}@10"
            if sensor.name == "imx500" and (not camera_id or camera_id in cam_id):
                return num, sensor
        raise RuntimeError("IMX500: Requested camera dev-node not found (no emulated imx500 camera: name one "
                           f"in ROLLCAM_PICAMERA2, e.g. 'imx500'; cameras: {sources()})")

    def __full(self) -> Rect:
        return (0, 0, self.__sensor.active_width, self.__sensor.active_height)

    @property
    def camera_num(self) -> int:
        """The camera number to open with ``Picamera2(imx500.camera_num)``."""
        return self.__num

    @property
    def config(self) -> dict[str, Any]:
        """The network's configuration: its file, input tensor size, region of interest (``roi``)."""
        return self.__cfg

    @property
    def network_intrinsics(self) -> NetworkIntrinsics | None:
        """What the network says about itself (task, box layout, COCO labels)."""
        return self.__cfg.get("intrinsics")

    def get_input_size(self) -> tuple[int, int]:
        """The network's input tensor size, (width, height)."""
        return self.__cfg["input_tensor_size"]

    def show_network_fw_progress_bar(self) -> None:
        """Nothing to show: the emulated sensor loads a network at once."""

    def get_fw_upload_progress(self, stage_req: int) -> tuple[int, int]:
        """The network upload's progress, (current, total): always finished here."""
        return (1, 1)

    def __set_input_tensor(self, input_tensor_fd: int) -> None:
        # Sony's modlib calls this by its mangled name (``_IMX500__set_input_tensor``) with a memfd holding the
        # tensor, then reads the comparison frame (``get_injection_cmp_frm``); errno 121 it retries.
        if not self.__injection:
            raise RuntimeError("IMX500: Unable to set input tensor fd: [Errno 22] Invalid argument (tensor injection "
                               "is off: IMX500(..., tensor_injection=True))")
        size = os.fstat(input_tensor_fd).st_size
        data = os.pread(input_tensor_fd, size, 0)
        try:
            self.__cmp_frm = _cnn.inject(self.__num, data)
        except InjectionBusy:
            e = RuntimeError(f"IMX500: Unable to set input tensor fd: [Errno {errno.EREMOTEIO}] Remote I/O error")
            e.errno = errno.EREMOTEIO  # type: ignore[attr-defined]
            raise e from None
        except ValueError as exc:
            raise RuntimeError(f"IMX500: Unable to set input tensor fd: {exc}") from None

    def get_injection_cmp_frm(self) -> int:
        """The frame counter (8 bits, ``CnnOutputTensorInfo.frameCount``) of the frame the last injected tensor
        runs on."""
        return self.__cmp_frm & 0xFF

    def input_tensor_image(self, input_tensor: Any) -> np.ndarray:
        """A request's ``CnnInputTensor`` as the 8-bit picture it shows, BGR (picamera2 reverses the planes)."""
        fmt = parse_tensor_format(self.__program.tensor if self.__program.tensor != "none" else
                                  resolve(self.__cfg["network_file"]).tensor())
        assert fmt is not None
        return fmt.picture_bgr(np.asarray(input_tensor, np.uint8))

    def get_device_id(self) -> str:
        """The sensor's unique id as 32 hex digits (derived from the camera number, stable)."""
        return hashlib.sha256(f"rollcam-imx500-{self.__num}".encode()).hexdigest()[:32].upper()

    @staticmethod
    def get_kpi_info(metadata: dict[str, Any]) -> tuple[float, float] | None:
        """(DNN runtime, DSP runtime) in ms of the frame's network run, or None."""
        kpi = metadata.get("CnnKpiInfo")
        if kpi is None:
            return None
        return kpi[0] / 1000, kpi[1] / 1000

    def __get_output_tensor_info(self, tensor_info: Any) -> dict[str, Any]:
        # picamera2's injection demo calls this by its mangled name for the frame counter (``frameCount``).
        fields = _cnn.TENSOR_INFO.unpack(bytes(tensor_info))
        per = 2 + _cnn.MAX_NUM_DIMENSIONS
        info = [{"tensor_data_num": fields[2 + i * per], "num_dimensions": fields[3 + i * per],
                 "size": list(fields[4 + i * per: 4 + i * per + fields[3 + i * per]])} for i in range(fields[1])]
        return {"network_name": fields[0].rstrip(b"\0").decode("utf-8"), "num_tensors": fields[1], "info": info,
                "frameCount": fields[-1]}

    def get_output_shapes(self, metadata: dict[str, Any]) -> list[list[int]]:
        """The shapes of the output tensors in ``metadata`` ([] when it has none)."""
        info = metadata.get("CnnOutputTensorInfo")
        if not info:
            return []
        fields = _cnn.TENSOR_INFO.unpack(bytes(info))
        count = fields[1]
        per = 2 + _cnn.MAX_NUM_DIMENSIONS
        shapes = []
        for i in range(count):
            ndim = fields[2 + i * per + 1]
            shapes.append(list(fields[2 + i * per + 2: 2 + i * per + 2 + ndim]))
        return shapes

    def get_outputs(self, metadata: dict[str, Any], add_batch: bool = False) -> list[np.ndarray] | None:
        """The output tensors in ``metadata`` as float32 arrays (``add_batch``: a leading axis of 1), or None."""
        flat = metadata.get("CnnOutputTensor")
        if not flat:
            return None
        data = np.asarray(flat, dtype=np.float32)
        out, offset = [], 0
        for shape in self.get_output_shapes(metadata):
            size = int(np.prod(shape))
            t = data[offset: offset + size].reshape(shape, order="F")
            out.append(np.expand_dims(t, 0) if add_batch else t)
            offset += size
        return out

    def convert_inference_coords(self, coords: Any, metadata: dict[str, Any], picam2: Any,
                                 stream: str = "main") -> Rect:
        """A box (y0, x0, y1, x1, normalised to the pixel array) in ``stream``'s pixels as (x, y, w, h)."""
        y0, x0, y1, x1 = (float(c) for c in coords)
        fw, fh = self.__full()[2:]
        obj = tuple(int(max(v, 0)) for v in (x0 * fw, y0 * fh, (x1 - x0) * fw, (y1 - y0) * fh))
        return self.__scaled_to(obj, picam2, metadata["ScalerCrop"], stream)  # type: ignore[arg-type]

    def get_roi_scaled(self, request: Any, stream: str = "main") -> Rect:
        """The inference region in ``stream``'s pixels."""
        return self.__scaled_to(self.__full(), request.picam2, request.get_metadata()["ScalerCrop"], stream)

    @staticmethod
    def get_isp_output_size(picam2: Any, stream: str = "main") -> tuple[int, int]:
        """The size of ``stream`` as configured."""
        return tuple(picam2.camera_configuration()[stream]["size"])  # type: ignore[return-value]

    def __scaled_to(self, obj: Rect, picam2: Any, scaler_crop: Rect, stream: str) -> Rect:
        # As picamera2 maps a rectangle: the pixel array -> the raw mode's pixels, within ScalerCrop, then
        # scaled to the ISP output.
        full = self.__full()
        out_size = self.get_isp_output_size(picam2, stream)
        raw_size = self.get_isp_output_size(picam2, "raw")
        crop = _scaled(tuple(int(v) for v in scaler_crop), raw_size, full[2:])  # type: ignore[arg-type]
        roi = self.__cfg.get("roi")
        if roi is not None and roi != (0, 0, 0, 0):
            obj = _bounded(obj, roi)
        r = _bounded(_scaled(obj, raw_size, full[2:]), crop)
        r = (r[0] - crop[0], r[1] - crop[1], r[2], r[3])
        return _scaled(r, out_size, crop[2:])

    def set_inference_roi_abs(self, roi: tuple[int, int, int, int]) -> None:
        """Run the network on ``roi`` (left, top, width, height in pixel-array coordinates) only."""
        r = _bounded(tuple(int(v) for v in roi), self.__full())  # type: ignore[arg-type]
        self.__cfg["roi"] = r
        _cnn.set_roi(self.__num, None if r == self.__full() else r)

    def set_inference_aspect_ratio(self, aspect_ratio: tuple[int, int]) -> None:
        """Run the network on the largest centred region of the array with this aspect ratio."""
        _, _, fw, fh = self.__full()
        aw, ah = (int(v) for v in aspect_ratio)
        w, h = (fw, fw * ah // aw) if fw * ah <= fh * aw else (fh * aw // ah, fh)
        self.set_inference_roi_abs(((fw - w) // 2, (fh - h) // 2, w, h))

    def set_auto_aspect_ratio(self) -> None:
        """Keep the input tensor's aspect ratio (a centred crop of the array)."""
        self.set_inference_aspect_ratio(self.get_input_size())
