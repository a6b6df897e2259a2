"""ONNX export of a trained detector, in the YOLO layout ``onnx:`` reads, with what it takes in its metadata.

PyTorch 2.13's default exporter (``dynamo=True``) needs the ``onnxscript`` package; its TorchScript exporter
(``dynamo=False``) needs nothing beyond torch and handles this plain convolutional graph, so rollcam uses it.
The input is fixed at the training size (``images [1, C, H, W]``), so ``onnx:`` takes the size from the model;
the metadata holds ``names`` (``{0: 'person'}``), ``rollcam_input`` (``bgr`` or ``raw``) and ``rollcam_bits``
(a raw model's sample depth), which the detector uses as its defaults, and ``rollcam_model`` (a JSON summary).

``load_onnx_weights`` goes the other way, so that a shipped ``model.onnx`` (which holds no checkpoint) can seed a
fine-tune: the exporter folds each BatchNorm into its convolution, and the import unfolds it again.
"""

from __future__ import annotations

import io
import json
import warnings
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from rollcam.common.errors import ConfigError, require
from rollcam.common.files import write_atomic
from torch import nn

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


def load_onnx_weights(net: PersonNet, path: str | Path, batches: Iterable[torch.Tensor]) -> None:
    """Load the weights of ``path``, a ``model.onnx`` that ``export_onnx`` wrote for the same model size, into
    ``net``; ConfigError when it does not fit.

    Export folded each BatchNorm into the convolution before it (``w' = w g / s``, ``b' = beta - m g / s``), which
    loses ``g`` and ``s``. The import sets each such pair to the same function in eval mode and then re-estimates
    the BatchNorm's statistics from ``batches`` (training images): the running mean and variance become those of
    the convolution's output ``w' x`` and the scale their standard deviation, so training-mode normalisation
    (batch statistics) starts where the exported model was, not at unit variance.
    """
    onnx = require("onnx", "onnx", "train", "rollcam train")
    from google.protobuf.message import DecodeError
    from onnx import numpy_helper

    try:
        model = onnx.load(str(path))
    except (OSError, DecodeError) as exc:
        raise ConfigError(f"--init {str(path)!r} is not an ONNX model ({exc})") from None
    consts = {t.name: numpy_helper.to_array(t) for t in model.graph.initializer}
    for node in model.graph.node:
        if node.op_type == "Constant":
            for attr in node.attribute:
                if attr.name == "value":
                    consts[node.output[0]] = numpy_helper.to_array(attr.t)
    onnx_convs = [(n.input[1], n.input[2] if len(n.input) > 2 else "") for n in model.graph.node
                  if n.op_type == "Conv"]
    order = _conv_order(net, model)
    bn_after = {id(m[0]): m[1] for m in net.modules()
                if isinstance(m, nn.Sequential) and len(m) > 1 and isinstance(m[0], nn.Conv2d)
                and isinstance(m[1], nn.BatchNorm2d)}

    def misfit(why: str) -> ConfigError:
        return ConfigError(f"--init {str(path)!r} does not fit this model ({why})")

    if len(onnx_convs) != len(order):
        raise misfit(f"{len(onnx_convs)} convolutions, the model has {len(order)}")
    with torch.no_grad():
        for k, (conv, (w_name, b_name)) in enumerate(zip(order, onnx_convs, strict=True)):
            if w_name not in consts:
                raise misfit(f"convolution {k} has no constant weights")
            w = torch.from_numpy(np.array(consts[w_name], np.float32))
            b = torch.from_numpy(np.array(consts[b_name], np.float32)) if b_name in consts else None
            if tuple(w.shape) != tuple(conv.weight.shape):
                raise misfit(f"convolution {k} is {tuple(w.shape)}, the model's is {tuple(conv.weight.shape)}")
            conv.weight.copy_(w)
            bn = bn_after.get(id(conv))
            bias = b if b is not None else torch.zeros(w.shape[0])
            if bn is not None:
                bn.weight.fill_(1.0)
                bn.bias.copy_(bias)
                bn.running_mean.zero_()
                bn.running_var.fill_(1.0 - bn.eps)  # (x - 0) / sqrt(1 - eps + eps) = x: the folded function
            elif conv.bias is not None:
                conv.bias.copy_(bias)
            elif b is not None and bool(b.abs().max() > 0):
                raise misfit(f"convolution {k} has a bias the model lacks")
    _calibrate(net, list(bn_after.values()), batches)


def _conv_order(net: PersonNet, model: Any) -> list[nn.Conv2d]:
    """``net``'s convolutions in the order a forward pass runs them (which is the exported graph's order)."""
    dims = [d.dim_value for d in model.graph.input[0].type.tensor_type.shape.dim]
    if len(dims) != 4 or dims[1] != net.in_channels or min(dims) <= 0:
        raise ConfigError(f"an ONNX input of shape {dims} does not fit a {net.in_channels}-channel PersonNet")
    seen: list[nn.Conv2d] = []
    hooks = [m.register_forward_hook(lambda mod, _i, _o: seen.append(mod)) for m in net.modules()
             if isinstance(m, nn.Conv2d)]
    was_training = net.training
    net.eval()
    try:
        with torch.no_grad():
            net(torch.zeros(1, *dims[1:]))
    finally:
        for h in hooks:
            h.remove()
        net.train(was_training)
    return seen


def _calibrate(net: PersonNet, bns: list[nn.BatchNorm2d], batches: Iterable[torch.Tensor]) -> None:
    """Re-express each folded BatchNorm with the statistics of its input over ``batches`` (see above)."""
    sums: dict[int, list[Any]] = {id(bn): [0, 0.0, 0.0] for bn in bns}

    def record(mod: nn.Module, inputs: tuple[torch.Tensor, ...]) -> None:
        x = inputs[0].double()
        acc = sums[id(mod)]
        acc[0] += x.shape[0] * x.shape[2] * x.shape[3]
        acc[1] = acc[1] + x.sum(dim=(0, 2, 3))
        acc[2] = acc[2] + (x * x).sum(dim=(0, 2, 3))

    hooks = [bn.register_forward_pre_hook(record) for bn in bns]
    was_training = net.training
    net.eval()
    try:
        with torch.no_grad():
            for x in batches:
                net(x)
    finally:
        for h in hooks:
            h.remove()
        net.train(was_training)
    with torch.no_grad():
        for bn in bns:
            n, s1, s2 = sums[id(bn)]
            if not n:
                continue
            mean = s1 / n
            var = (s2 / n - mean * mean).clamp(min=0.0)
            bn.running_mean.copy_(mean.float())
            bn.running_var.copy_(var.float())
            bn.bias.add_(mean.float())  # scale sqrt(var + eps), shift b' + mean: the same function as before
            bn.weight.copy_(torch.sqrt(var + bn.eps).float())
