"""rollcam's own person detector: a small anchor-free network in plain PyTorch, written for this project (MIT).

Shape (docs/training.md argues the choice): a MobileNet-like backbone of depthwise-separable blocks down to
stride 32, a top-down feature pyramid merged back to one stride-4 map, and a CenterNet/TTFNet-style head on it:
one person heatmap channel and four box distances (left, top, right, bottom, in strides) per cell. One output
stride keeps the decoder trivial; stride 4 keeps the study's smallest labelled walkers (16 px tall at 1080p,
about 5 px at 640x360) on a cell of their own.

``Exported`` wraps the network for ONNX: it decodes in the graph to the YOLO layout that ``onnx:`` reads
(``[1, 5, N]``: cx, cy, w, h in input pixels, then the person score), keeping only each 3x3 local maximum of the
heatmap (CenterNet's peak pick), so the detector's NMS sees a handful of candidates, not every cell.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from rollcam.common.errors import ConfigError
from torch import nn

STRIDE = 4
"""Output stride of the head (input pixels per heatmap cell)."""


@dataclass(frozen=True)
class ModelSize:
    """Channel widths of one model size: stem, the four backbone stages, the neck/head; blocks per stage."""

    stem: int
    stages: tuple[int, int, int, int]
    neck: int
    depth: tuple[int, int, int, int]


SIZES = {
    "pico": ModelSize(8, (16, 24, 32, 48), 16, (1, 1, 1, 1)),    # tests: ~20k parameters
    "nano": ModelSize(16, (24, 48, 96, 160), 48, (1, 2, 3, 2)),
    "small": ModelSize(24, (32, 64, 128, 224), 64, (2, 2, 4, 2)),
}
"""``--model`` names -> widths. The packaged ``personnet`` detector is ``nano``; ``personnet-raw`` is ``pico``."""


def model_size(name: str) -> ModelSize:
    """The widths of size ``name``; a ConfigError naming the known sizes otherwise."""
    if name not in SIZES:
        raise ConfigError(f"--model {name!r} is not one of {list(SIZES)}")
    return SIZES[name]


def _conv_bn(cin: int, cout: int, k: int = 3, stride: int = 1, groups: int = 1, act: bool = True) -> nn.Sequential:
    layers: list[nn.Module] = [nn.Conv2d(cin, cout, k, stride, k // 2, groups=groups, bias=False),
                               nn.BatchNorm2d(cout)]
    if act:
        layers.append(nn.ReLU(inplace=True))
    return nn.Sequential(*layers)


class SepBlock(nn.Module):
    """Depthwise 3x3 then pointwise 1x1 (MobileNet); residual when the shape is kept."""

    def __init__(self, cin: int, cout: int, stride: int = 1) -> None:
        super().__init__()
        self.dw = _conv_bn(cin, cin, 3, stride, groups=cin)
        self.pw = _conv_bn(cin, cout, 1, act=stride != 1 or cin != cout)
        self.residual = stride == 1 and cin == cout

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.pw(self.dw(x))
        return F.relu(x + y) if self.residual else y


class PersonNet(nn.Module):
    """Backbone, feature pyramid and the heatmap/box head; ``forward`` gives raw (heat logits, box) maps."""

    def __init__(self, size: ModelSize, in_channels: int = 3) -> None:
        super().__init__()
        self.in_channels = in_channels
        self.stem = _conv_bn(in_channels, size.stem, 3, 2)
        stages, cin = [], size.stem
        for cout, n in zip(size.stages, size.depth, strict=True):
            stages.append(nn.Sequential(SepBlock(cin, cout, 2), *(SepBlock(cout, cout) for _ in range(n))))
            cin = cout
        self.stages = nn.ModuleList(stages)
        self.lateral = nn.ModuleList(_conv_bn(c, size.neck, 1) for c in size.stages)
        self.smooth = nn.ModuleList(SepBlock(size.neck, size.neck) for _ in size.stages[:-1])
        self.head = nn.Sequential(SepBlock(size.neck, size.neck), SepBlock(size.neck, size.neck))
        self.heat = nn.Conv2d(size.neck, 1, 1)
        self.box = nn.Conv2d(size.neck, 4, 1)
        # Focal-loss practice (RetinaNet): start every cell at p = 0.01, so the first steps are not swamped by
        # the loss of the many background cells.
        nn.init.constant_(self.heat.bias, -4.6)
        nn.init.constant_(self.box.bias, 1.0)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        feats = []
        y = self.stem(x)
        for stage in self.stages:
            y = stage(y)
            feats.append(y)
        top = self.lateral[-1](feats[-1])
        for i in range(len(feats) - 2, -1, -1):
            lat = self.lateral[i](feats[i])
            # Upsample to the skip's own size: odd sizes (360 / 8 = 45) do not halve evenly.
            top = self.smooth[i](lat + F.interpolate(top, size=lat.shape[-2:], mode="nearest"))
        h = self.head(top)
        return self.heat(h), F.softplus(self.box(h))


def cell_centres(height: int, width: int, device: torch.device | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Centres (x, y) in input pixels of a ``height`` x ``width`` stride-4 grid, each shaped (height, width)."""
    ys = (torch.arange(height, dtype=torch.float32, device=device) + 0.5) * STRIDE
    xs = (torch.arange(width, dtype=torch.float32, device=device) + 0.5) * STRIDE
    return xs[None, :].expand(height, width), ys[:, None].expand(height, width)


def decode_boxes(box: torch.Tensor) -> torch.Tensor:
    """Box maps (B, 4, h, w) of (l, t, r, b) in strides -> (B, 4, h, w) x0, y0, x1, y1 in input pixels."""
    cx, cy = cell_centres(box.shape[2], box.shape[3], box.device)
    d = box * STRIDE
    return torch.stack([cx - d[:, 0], cy - d[:, 1], cx + d[:, 2], cy + d[:, 3]], dim=1)


class Exported(nn.Module):
    """The network with its decoder: an NCHW image in 0..1 -> ``[B, 5, N]`` (cx, cy, w, h, score)."""

    def __init__(self, net: PersonNet) -> None:
        super().__init__()
        self.net = net

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        logits, box = self.net(x)
        score = torch.sigmoid(logits)
        peak = F.max_pool2d(score, 3, 1, 1)
        score = score * (score == peak).to(score.dtype)
        xyxy = decode_boxes(box)
        wh = xyxy[:, 2:] - xyxy[:, :2]
        out = torch.cat([xyxy[:, :2] + wh / 2, wh, score], dim=1)
        return out.flatten(2)


def count_parameters(net: nn.Module) -> int:
    """Parameters of ``net``, the model's size (frozen ones too: the exported moving average of ``--ema`` holds
    its weights without gradients)."""
    return sum(p.numel() for p in net.parameters())
