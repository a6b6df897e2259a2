"""The IMX500's input tensor: what the sensor's ISP makes of a picture before its network sees it.

On the Raspberry Pi AI Camera the network never sees the image a host gets: the sensor's own ISP crops the
picture to the inference region, scales it to the network's input tensor (no padding: an aspect ratio is kept by
a centred crop), orders the channels as the network wants them (RGB or BGR), pads each row to a multiple of 32
samples and the height to an even number (the DSP's layout), lays the planes out one after another (C, H, W) and
maps every 8-bit sample to the network's quantised input in fixed point:

    q = (((x * div_val[c]) >> div_shift) + norm_val[c]) >> norm_shift[c]      (arithmetic shifts: floor)

stored as uint8 or int8. ``div_val`` is a 12-bit and ``norm_val`` a 13-bit two's-complement register field per
channel, ``div_shift`` 6 and ``norm_shift`` 4 (the fields of a network package's ``network_info.txt``:
``inputTensorNorm_K00`` ... ``K23``); together they approximate ``q = x * scale / std - scale * mean / std +
shift``. Sony's ``modlib`` reproduces this path on a host (``modlib.devices.imx500.isp``:
``prepare_tensor_like_isp``) to make tensors that are injected into a real sensor; ``InputTensorFormat.prepare``
gives the same bytes for the same picture (tests/test_input_tensor.py compares them with modlib's own code), so a
tensor made for a real AI Camera runs on the emulated one and the other way round. ``picture`` is the way back
(modlib's ``isp_denormalize_input_tensor``, picamera2's ``IMX500.input_tensor_image``): the 8-bit picture the
network saw.

The in-sensor stage uses it when a camera's network takes an input tensor (``insensor_tensor=WxH...``): the
network runs on ``picture(prepare(image))``, the result carries the tensor (``InSensorResult.input_tensor``, the
picamera2 stand-in's ``CnnInputTensor``), and a tensor injected into the camera (``InSensorStage.inject``) takes
the place of the frame's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from rollcam.common.errors import ConfigError
from rollcam.common.values import parse_size

COLORS = ("RGB", "BGR")
"""Channel orders a network's input tensor can have."""
DIV_SHIFT = 6
NORM_SHIFT = 4
"""The IMX500's fixed shifts (``div_shift``, and ``norm_shift`` of every channel)."""
DIV_BITS = 12
NORM_BITS = 13
"""Widths of the two's-complement ``div_val`` and ``norm_val`` register fields."""
ROW_ALIGN = 32
"""The DSP reads rows padded to a multiple of this many samples."""
MAX_SIDE = 4096


def _fits(value: int, bits: int) -> bool:
    return -(1 << (bits - 1)) <= value < (1 << (bits - 1))


@dataclass(frozen=True)
class InputTensorFormat:
    """A network's input tensor as the IMX500's ISP makes it (see the module docstring)."""

    width: int
    height: int
    color: str = "RGB"
    norm_val: tuple[int, int, int] = (0, 0, 0)
    div_val: tuple[int, int, int] = (1024, 1024, 1024)
    signed: bool = False
    preserve_aspect_ratio: bool = False
    norm_shift: tuple[int, int, int] = (NORM_SHIFT,) * 3
    div_shift: int = DIV_SHIFT

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            v = getattr(self, name)
            if not (isinstance(v, int) and 1 <= v <= MAX_SIDE):
                raise ConfigError(f"input tensor {name} {v!r} must be a whole number 1..{MAX_SIDE}")
        if self.color not in COLORS:
            raise ConfigError(f"input tensor colour order {self.color!r} is not one of {COLORS}")
        for name, bits in (("norm_val", NORM_BITS), ("div_val", DIV_BITS)):
            values = tuple(getattr(self, name))
            if len(values) != 3 or not all(isinstance(v, int) and _fits(v, bits) for v in values):
                raise ConfigError(f"input tensor {name} {values!r} must be 3 whole numbers in a {bits}-bit "
                                  "two's-complement register field")
            object.__setattr__(self, name, values)
        if not all(v != 0 for v in self.div_val):
            raise ConfigError(f"input tensor div_val {self.div_val!r} has a zero (no way back to the picture)")
        if not (all(0 <= s <= 15 for s in self.norm_shift) and 0 <= self.div_shift <= 15):
            raise ConfigError(f"input tensor shifts {self.norm_shift!r}, {self.div_shift!r} must be 0..15")

    @classmethod
    def from_normalization(cls, width: int, height: int, mean: Any = 0.0, std: Any = 1.0, scale: float = 1.0,
                           shift: float = 0.0, color: str = "RGB", signed: bool = False,
                           preserve_aspect_ratio: bool = False) -> InputTensorFormat:
        """The fixed-point registers nearest to ``q = (x - mean) / std * scale + shift`` (per channel; ``mean``
        and ``std`` in 8-bit units, one value or three): ``div_val = round(scale / std * 2^10)``, ``norm_val =
        round((shift - scale * mean / std) * 2^4)``."""
        mean3 = np.broadcast_to(np.asarray(mean, np.float64), (3,))
        std3 = np.broadcast_to(np.asarray(std, np.float64), (3,))
        if not (np.all(np.isfinite(mean3)) and np.all(np.isfinite(std3)) and np.all(std3 != 0)):
            raise ConfigError(f"input normalisation mean {mean!r}, std {std!r}: finite, std not 0")
        a = scale / std3
        b = shift - scale * mean3 / std3
        div = tuple(int(round(v * (1 << (DIV_SHIFT + NORM_SHIFT)))) for v in a)
        norm = tuple(int(round(v * (1 << NORM_SHIFT))) for v in b)
        return cls(width, height, color, norm, div, signed, preserve_aspect_ratio)  # type: ignore[arg-type]

    @property
    def dtype(self) -> np.dtype:
        """The tensor's sample type: int8 or uint8."""
        return np.dtype(np.int8 if self.signed else np.uint8)

    @property
    def padded_size(self) -> tuple[int, int]:
        """(width, height) as the DSP lays the planes out: rows to a multiple of 32, the height even."""
        return (-(-self.width // ROW_ALIGN) * ROW_ALIGN, self.height + self.height % 2)

    @property
    def nbytes(self) -> int:
        """Bytes of one tensor (three padded planes)."""
        w, h = self.padded_size
        return 3 * w * h

    def crop(self, size: tuple[int, int]) -> tuple[int, int, int, int]:
        """The part ``(x, y, w, h)`` of a ``size`` picture the tensor shows: all of it, or (aspect ratio kept)
        the centred crop of the tensor's aspect ratio, rounded down as the sensor's firmware does."""
        img_w, img_h = size
        if not self.preserve_aspect_ratio:
            return (0, 0, img_w, img_h)
        model, image = self.width / self.height, img_w / img_h
        w, h = (img_w, int(image / model * img_h)) if model > image else (int(model / image * img_w), img_h)
        x, y = int((img_w - w) / 2), int((img_h - h) / 2)
        # The crop is carried as fractions of the picture, and cut at their products rounded down.
        left, top, fw, fh = x / img_w, y / img_h, w / img_w, h / img_h
        x0, x1 = int(left * img_w), int((left + fw) * img_w)
        y0, y1 = int(top * img_h), int((top + fh) * img_h)
        return (x0, y0, x1 - x0, y1 - y0)

    def scaled(self, image_bgr: np.ndarray) -> np.ndarray:
        """The picture (8-bit BGR, H x W x 3) cropped and scaled to the tensor's size, in its colour order."""
        import cv2

        image = np.asarray(image_bgr)
        if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
            raise ValueError(f"an input tensor is made from an 8-bit H x W x 3 picture, not {image.dtype} "
                             f"{image.shape}")
        x, y, w, h = self.crop((image.shape[1], image.shape[0]))
        scaled = cv2.resize(image[y:y + h, x:x + w], (self.width, self.height))  # bilinear, as the ISP
        return scaled[:, :, ::-1] if self.color == "RGB" else scaled

    def quantize(self, planes: np.ndarray) -> np.ndarray:
        """8-bit samples (3, H, W) in fixed point: the quantised planes, in the tensor's dtype."""
        t = np.asarray(planes).astype(np.int32)
        for c in range(3):
            t[c] = (((t[c] * self.div_val[c]) >> self.div_shift) + self.norm_val[c]) >> self.norm_shift[c]
        return t.astype(self.dtype)

    def prepare(self, image_bgr: np.ndarray) -> np.ndarray:
        """The tensor the sensor makes of a picture (8-bit BGR), flat: (3, H', W') planes of ``padded_size``."""
        w, h = self.padded_size
        scaled = self.scaled(image_bgr)
        padded = np.zeros((h, w, 3), np.uint8)
        padded[: self.height, : self.width] = scaled
        return self.quantize(np.ascontiguousarray(padded.transpose(2, 0, 1))).ravel()

    def planes(self, tensor: Any) -> np.ndarray:
        """A tensor (flat, padded or not, any 8-bit type or bytes) as its (3, height, width) planes of raw 8-bit
        codes; ValueError naming the sizes when it is neither."""
        raw = np.frombuffer(tensor, np.uint8) if isinstance(tensor, (bytes, bytearray, memoryview)) else \
            np.asarray(tensor).astype(self.dtype, copy=False).view(np.uint8)
        pw, ph = self.padded_size
        if raw.size == 3 * self.width * self.height:
            return raw.reshape(3, self.height, self.width)
        if raw.size == 3 * pw * ph:
            return raw.reshape(3, ph, pw)[:, : self.height, : self.width]
        raise ValueError(f"an input tensor of {raw.size} samples is not 3x{self.height}x{self.width} nor the "
                         f"padded 3x{ph}x{pw} ({self.nbytes} bytes)")

    def picture(self, tensor: Any) -> np.ndarray:
        """The 8-bit picture a tensor shows (H x W x 3 in the tensor's colour order): the quantisation undone,
        ``((q << norm_shift) - norm_val) << div_shift) // div_val``, kept to 8 bits."""
        r = self.planes(tensor).astype(np.int32)
        for c in range(3):
            r[c] = ((((r[c] << self.norm_shift[c]) - self.norm_val[c]) << self.div_shift) // self.div_val[c]) & 0xFF
        return np.ascontiguousarray(r.transpose(1, 2, 0).astype(np.uint8))

    def picture_bgr(self, tensor: Any) -> np.ndarray:
        """``picture`` in BGR order (what rollcam's detectors take)."""
        pic = self.picture(tensor)
        return np.ascontiguousarray(pic[:, :, ::-1]) if self.color == "RGB" else pic

    def to_text(self) -> str:
        """The ``insensor_tensor`` option text that gives this format."""
        parts = [f"{self.width}x{self.height}", self.color.lower(), "int8" if self.signed else "uint8"]
        if self.preserve_aspect_ratio:
            parts.append("crop")
        if self.norm_val != (0, 0, 0):
            parts.append("norm=" + "/".join(str(v) for v in self.norm_val))
        if self.div_val != (1024,) * 3:
            parts.append("div=" + "/".join(str(v) for v in self.div_val))
        return ",".join(parts)


def parse_tensor_format(text: str) -> InputTensorFormat | None:
    """An ``insensor_tensor`` option: ``none``, or ``WxH`` then any of ``rgb``/``bgr``, ``uint8``/``int8``,
    ``crop`` (keep the aspect ratio), ``norm=A/B/C`` and ``div=A/B/C`` (the register fields; one value for all
    three channels). ``int8`` without ``norm=`` centres the samples (``norm=-2048``: q = x - 128)."""
    word = str(text).strip()
    if word.lower() in ("", "none", "off"):
        return None
    parts = [p.strip() for p in word.split(",") if p.strip()]
    try:
        w, h = parse_size(parts[0])
    except ConfigError:
        raise ValueError(f"expected WxH first, as 224x224, not {parts[0]!r}") from None
    kw: dict[str, Any] = {}
    for p in parts[1:]:
        key, _, value = p.partition("=")
        key = key.lower()
        if key in ("rgb", "bgr") and not value:
            kw["color"] = key.upper()
        elif key in ("uint8", "int8") and not value:
            kw["signed"] = key == "int8"
        elif key == "crop" and not value:
            kw["preserve_aspect_ratio"] = True
        elif key in ("norm", "div") and value:
            try:
                vals = [int(v) for v in value.split("/")]
            except ValueError:
                raise ValueError(f"{key}= takes whole numbers A/B/C, not {value!r}") from None
            if len(vals) not in (1, 3):
                raise ValueError(f"{key}= takes one value or three (A/B/C), not {value!r}")
            kw[f"{key}_val"] = tuple(vals * 3 if len(vals) == 1 else vals)
        else:
            raise ValueError(f"unknown input tensor part {p!r} (expected rgb, bgr, uint8, int8, crop, norm=, div=)")
    if kw.get("signed") and "norm_val" not in kw:
        kw["norm_val"] = (-128 << NORM_SHIFT,) * 3
    try:
        return InputTensorFormat(w, h, **kw)
    except ConfigError as e:
        raise ValueError(str(e)) from None

