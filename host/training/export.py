"""ONNX export of a trained detector, in the YOLO layout ``onnx:`` reads, with what it takes in its metadata.

PyTorch 2.13's default exporter (``dynamo=True``) needs the ``onnxscript`` package; its TorchScript exporter
(``dynamo=False``) needs nothing beyond torch and handles this plain convolutional graph, so rollcam uses it.
The input is fixed at the training size (``images [1, C, H, W]``), so ``onnx:`` takes the size from the model;
the metadata holds ``names`` (``{0: 'person'}``), ``rollcam_input`` (``bgr`` or ``raw``) and ``rollcam_bits``
(a raw model's sample depth), which the detector uses as its defaults, and ``rollcam_model`` (a JSON summary).
"""

from __future__ import annotations

import io
import json
import warnings
from pathlib import Path
from typing import Any

import torch
from rollcam.common.errors import require
from rollcam.common.files import write_atomic

from .model import Exported, PersonNet

OPSET = 17


def export_onnx(net: PersonNet, path: str | Path, width: int, height: int, *, input: str = "bgr",
                bits: int | None = None, info: dict[str, Any] | None = None) -> Path:
    """Write ``net`` with its decoder as an ONNX model at ``path`` (atomically); returns the path."""
    onnx = require("onnx", "onnx", "train", "rollcam train")
    was_training = net.training
    net.eval()
    try:
        buf = io.BytesIO()
        x = torch.zeros(1, net.in_channels, height, width)
        with warnings.catch_warnings(), torch.no_grad():
            warnings.simplefilter("ignore")  # the TorchScript exporter's deprecation notice, said once in docs
            torch.onnx.export(Exported(net), (x,), buf, dynamo=False, opset_version=OPSET, input_names=["images"],
                              output_names=["output0"], do_constant_folding=True)
    finally:
        net.train(was_training)
    model = onnx.load_from_string(buf.getvalue())
    meta = {"names": "{0: 'person'}", "rollcam_input": input, "rollcam_model": json.dumps(info or {}, sort_keys=True)}
    if bits is not None:
        meta["rollcam_bits"] = str(bits)
    for key, value in meta.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = key, value
    model.producer_name = "rollcam train"
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(out, model.SerializeToString())
    return out
