"""The IMX500's input tensor path (``rollcam.firmware.input_tensor``) against Sony's own host copy of it, modlib's
``modlib.devices.imx500.isp``, on the emulated camera's frames.

modlib pins older numpy and OpenCV than rollcam, so it is not installed: ``make modlib-ref`` unpacks its wheel
(``pip download --no-deps``) into ``.modlib/site`` (or name another folder in ``ROLLCAM_MODLIB``) and these tests
import its modules from there, on rollcam's numpy and OpenCV. Without it they skip, naming what is missing.
"""

from __future__ import annotations

import importlib
import os
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from rollcam.common.errors import ConfigError
from rollcam.firmware.input_tensor import InputTensorFormat, parse_tensor_format
from rollcam.host import open_camera

ROOT = Path(__file__).resolve().parents[1]


def modlib_isp():
    """modlib's isp module, imported from the unpacked wheel; skips when it is not there."""
    where = Path(os.environ.get("ROLLCAM_MODLIB", ROOT / ".modlib" / "site"))
    if not (where / "modlib" / "devices" / "imx500" / "isp.py").is_file():
        pytest.skip(f"Sony's modlib is not unpacked in {where} (make modlib-ref, or ROLLCAM_MODLIB=DIR)")
    if str(where) not in sys.path:
        sys.path.insert(0, str(where))
    return importlib.import_module("modlib.devices.imx500.isp")


def model_of(fmt: InputTensorFormat):
    """What modlib's isp functions read of a ``Model``: the attributes its rpk parser fills."""
    return SimpleNamespace(
        input_tensor_size=(fmt.width, fmt.height), preserve_aspect_ratio=fmt.preserve_aspect_ratio,
        color_format=fmt.color,
        info={"input_tensor": {"norm_val": list(fmt.norm_val), "norm_shift": list(fmt.norm_shift),
                               "div_val": list(fmt.div_val), "div_shift": fmt.div_shift,
                               "dtype": np.int8 if fmt.signed else np.uint8}})


@pytest.fixture(scope="module")
def pictures():
    """ISP pictures of the emulated AI Camera (a street with people), 4:3 and a cropped odd-sided one."""
    with open_camera("emu:imx500?size=506x380&pedestrians=6&frames=2") as cam:
        frames = [f.data for f in cam]
    return [frames[0], frames[1], np.ascontiguousarray(frames[1][7:300, 3:482])]


FORMATS = [
    InputTensorFormat(224, 224),  # a classifier's RGB 0..255
    InputTensorFormat.from_normalization(224, 224, mean=(123.675, 116.28, 103.53), std=(58.395, 57.12, 57.375),
                                         scale=1 / 0.0187, shift=-14, signed=True, preserve_aspect_ratio=True),
    InputTensorFormat(321, 241, color="BGR", norm_val=(-2048, -2000, -1900), div_val=(1024, 900, 2047),
                      signed=True),  # padded: rows to 352, height to 242; values wrap as the int8 cast does
    InputTensorFormat(300, 200, norm_val=(100, -4096, 4095), div_val=(-2048, 1500, 700), preserve_aspect_ratio=True),
    parse_tensor_format("640x480,bgr,crop"),
]


@pytest.mark.parametrize("fmt", FORMATS, ids=lambda f: f.to_text())
def test_the_tensor_is_modlibs_byte_for_byte(pictures, fmt):
    isp = modlib_isp()
    from modlib.models import COLOR_FORMAT

    for picture in pictures:
        ours = fmt.prepare(picture)
        theirs, roi = isp.prepare_tensor_like_isp(picture, model_of(fmt), COLOR_FORMAT.BGR)
        assert ours.dtype == theirs.dtype and ours.shape == theirs.shape == (fmt.nbytes,)
        assert np.array_equal(ours, theirs)
        # The crop is the region modlib reports.
        h, w = picture.shape[:2]
        x, y, cw, ch = fmt.crop((w, h))
        assert (x, y, x + cw, y + ch) == (int(roi.left * w), int(roi.top * h), int((roi.left + roi.width) * w),
                                          int((roi.top + roi.height) * h))
        # And the way back is modlib's.
        assert np.array_equal(fmt.picture(ours), isp.isp_denormalize_input_tensor(theirs, model_of(fmt)))


def test_the_picture_comes_back_where_the_norm_is_invertible(pictures):
    """With a whole-number gain (div 1024: q = x + b) the tensor holds the scaled picture exactly."""
    fmt = parse_tensor_format("200x150,int8")
    tensor = fmt.prepare(pictures[0])
    assert tensor.dtype == np.int8 and tensor.size == 3 * 224 * 150
    assert np.array_equal(fmt.picture(tensor), fmt.scaled(pictures[0]))
    assert np.array_equal(fmt.picture(tensor.tobytes()), fmt.scaled(pictures[0]))  # as bytes, as injected
    planes = tensor.reshape(3, 150, 224)
    assert np.all(planes[:, :, 200:] == -128)  # the padding is zeros, quantised as any sample


def test_registers_from_a_normalization_match_modlibs_scale_and_shift():
    isp = modlib_isp()
    mean, std, scale, shift = (123.675, 116.28, 103.53), (58.395, 57.12, 57.375), 1 / 0.0187, -14.0
    fmt = InputTensorFormat.from_normalization(224, 224, mean, std, scale, shift, signed=True)
    got_scale, got_shift = isp.extract_scale_and_shift(mean, std, list(fmt.norm_val), list(fmt.norm_shift),
                                                       list(fmt.div_val), fmt.div_shift)
    assert np.allclose(got_scale, scale, rtol=2e-3) and np.allclose(got_shift, shift, atol=1 / 16)


def test_bad_formats_are_named():
    with pytest.raises(ConfigError, match=r"div_val .* 12-bit"):
        InputTensorFormat(8, 8, div_val=(4096, 1024, 1024))
    with pytest.raises(ConfigError, match="colour order 'YUV'"):
        InputTensorFormat(8, 8, color="YUV")
    with pytest.raises(ValueError, match="unknown input tensor part 'fp16'"):
        parse_tensor_format("224x224,fp16")
    with pytest.raises(ValueError, match="expected WxH first"):
        parse_tensor_format("rgb,224x224")
    fmt = InputTensorFormat(10, 10)
    with pytest.raises(ValueError, match="not 3x10x10 nor the padded 3x10x32"):
        fmt.picture(np.zeros(7, np.uint8))
    with pytest.raises(ValueError, match="8-bit H x W x 3 picture"):
        fmt.prepare(np.zeros((4, 4), np.uint8))
