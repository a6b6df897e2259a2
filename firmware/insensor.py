"""The in-sensor network's programming: which network, on what input, within which compute budget.

An intelligent vision sensor (Sony's IMX500 is the one on sale) runs a network on its own logic die and sends
its output beside the image, or instead of it. The emulated camera does the same (``insensor_stage`` runs it):
``CameraSpec.insensor`` is an ``InSensorConfig`` built from the option table's ``insensor*`` options:

- ``insensor=SPEC``: any rollcam detector spec (``personnet-raw``, ``personnet``, ``onnx:PATH``, ``hog``);
- ``insensor_input=raw|isp``: the raw mosaic (no ISP: what the sensor really has) or the ISP's picture
  (default: what the network says it takes);
- ``insensor_size=WxH``: the largest input the accelerator takes; a larger frame is binned by a whole factor
  first (colour sites kept: a Bayer mosaic is binned site by site), as a sensor's input-tensor path scales;
- ``insensor_roi=X,Y,W,H``: the part of the frame the network sees (frame pixels; default the whole frame),
  as the IMX500's inference region of interest; boxes still come back in the frame's pixels;
- ``insensor_tensor=WxH,...``: the network takes an IMX500 input tensor (``rollcam.firmware.input_tensor``): the
  ISP's picture of the region cropped and scaled to it, its channel order and fixed-point normalisation; the
  network runs on the picture the tensor shows, and a tensor can be injected in place of the frame's;
- ``insensor_accel=NAME|GMACS``: the accelerator profile (``ACCELERATORS``) or a throughput in GMAC/s; the
  latency of a frame is the network's multiply-accumulates at its input size over the throughput;
- ``insensor_output=frame|meta``: the image and the results, or the results only (metadata-only mode: the
  image never leaves the chip).

Networks are host objects (detectors live in ``rollcam.host``), so the firmware names them through a loader
the host registers (``set_network_loader``: ``import rollcam.host`` does it); the firmware holds only the
``Network`` protocol. Loaded networks are cached by spec text, so a spec is checked (and its model loaded) once
when it is made and every camera with the same spec shares one network.
"""

from __future__ import annotations

import importlib
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from rollcam.common.errors import ConfigError

from .input_tensor import InputTensorFormat

OUTPUTS = ("frame", "meta")
"""``frame``: image and results; ``meta``: results only (metadata-only mode)."""
DEFAULT_MAX_SIZE = (640, 640)
"""Largest network input by default, px (a 640x640 input tensor, the size of the usual detection exports)."""
MAX_SPEC = 256
"""Longest network spec, characters."""


@dataclass(frozen=True)
class Accelerator:
    """An accelerator profile: sustained multiply-accumulates per second, energy per MAC, and where each
    figure comes from (docs/insensor.md cites them)."""

    name: str
    macs_per_s: float
    pj_per_mac: float
    source: str

    def latency_ns(self, macs: int) -> int:
        """Modelled time of one inference of ``macs`` multiply-accumulates, whole ns rounded up."""
        return math.ceil(macs * 1e9 / self.macs_per_s)

    def energy_pj(self, macs: int) -> float:
        """Modelled energy of one inference, pJ."""
        return macs * self.pj_per_mac


IMX500_MACS_PER_S = 569e6 / 3.1e-3
"""Sony: MobileNet V1 (569 M multiply-adds at 224x224, Howard et al. 2017) runs in 3.1 ms on the IMX500."""
IMX500_PJ_PER_MAC = 2 / 4.97
"""Eki et al., ISSCC 2021: the IMX500's CNN processor reaches 4.97 TOPS/W (two operations per MAC)."""

ACCELERATORS = {a.name: a for a in (
    Accelerator("imx500", IMX500_MACS_PER_S, IMX500_PJ_PER_MAC,
                "Sony IMX500 press release (2020): MobileNet V1 in 3.1 ms; Eki et al., ISSCC 2021: 4.97 TOPS/W"),
)}
"""Accelerator profiles by name; ``insensor_accel=N`` (a number) is a custom one of N GMAC/s at the IMX500's
energy per MAC."""


def accelerator(text: str) -> Accelerator:
    """An accelerator by profile name, or a custom one of ``text`` GMAC/s."""
    word = str(text).strip().lower()
    if word in ACCELERATORS:
        return ACCELERATORS[word]
    try:
        gmacs = float(word)
    except ValueError:
        raise ValueError(f"expected one of {sorted(ACCELERATORS)} or a throughput in GMAC/s") from None
    if not (math.isfinite(gmacs) and 1e-6 <= gmacs <= 1e6):
        raise ValueError("a throughput must be 1e-6..1e6 GMAC/s")
    return Accelerator(f"{gmacs:g}GMACs", gmacs * 1e9, IMX500_PJ_PER_MAC, "custom throughput (energy: the IMX500's)")


def output_mode(text: str) -> str:
    """``frame`` (also ``frame+meta``) or ``meta``."""
    word = str(text).strip().lower().replace(" ", "+")
    word = {"frame+meta": "frame", "both": "frame"}.get(word, word)
    if word not in OUTPUTS:
        raise ValueError("expected frame (frame+meta) or meta")
    return word


def parse_roi(text: str) -> tuple[int, int, int, int] | None:
    """An input region ``x,y,w,h`` (frame pixels, w and h at least 2), or None for ``none``/``full``."""
    word = str(text).strip().lower()
    if word in ("", "none", "full"):
        return None
    parts = word.replace(" ", "").split(",")
    try:
        x, y, w, h = (int(p) for p in parts)
    except ValueError:
        raise ValueError("expected x,y,w,h in whole frame pixels, or none") from None
    if min(x, y) < 0 or min(w, h) < 2 or max(x + w, y + h) > 65536:
        raise ValueError("expected x, y >= 0 and w, h >= 2 within 65536 pixels")
    return (x, y, w, h)


def roi_in(roi: tuple[int, int, int, int] | None, size: tuple[int, int], even: bool) -> tuple[int, int, int, int]:
    """The input region within a ``size`` frame (the whole frame for None); ``even``: whole Bayer tiles (even
    offsets and sizes), so the mosaic's colour pattern is the frame's."""
    fw, fh = size
    x, y, w, h = roi or (0, 0, fw, fh)
    x, y = min(x, fw - 2), min(y, fh - 2)
    w, h = max(min(w, fw - x), 2), max(min(h, fh - y), 2)
    if even:
        x, y, w, h = x - x % 2, y - y % 2, max(w - w % 2, 2), max(h - h % 2, 2)
    return (x, y, w, h)


def network_spec(text: str) -> str | None:
    """A network spec as text (None for ``none``/``off``), printable ASCII of at most ``MAX_SPEC``."""
    spec = str(text).strip()
    if spec.lower() in ("", "none", "off"):
        return None
    if len(spec) > MAX_SPEC or not spec.isascii() or not spec.isprintable():
        raise ValueError(f"a network spec is 1..{MAX_SPEC} printable ASCII characters")
    return spec


@dataclass(frozen=True)
class InSensorConfig:
    """The in-sensor network's programming (see the module docstring); ``input`` None: the network's own."""

    network: str
    input: str | None = None
    max_size: tuple[int, int] = DEFAULT_MAX_SIZE
    accel: Accelerator = ACCELERATORS["imx500"]
    output: str = "frame"
    roi: tuple[int, int, int, int] | None = None
    tensor: InputTensorFormat | None = None

    def __post_init__(self) -> None:
        if self.input not in (None, "raw", "isp"):
            raise ConfigError(f"insensor_input {self.input!r} is not raw or isp")
        if self.output not in OUTPUTS:
            raise ConfigError(f"insensor_output {self.output!r} is not one of {OUTPUTS}")
        w, h = self.max_size
        if not (isinstance(w, int) and isinstance(h, int) and 2 <= w <= 8192 and 2 <= h <= 8192):
            raise ConfigError(f"insensor_size {self.max_size!r} must be 2..8192 a side")
        if self.tensor is not None and self.input == "raw":
            raise ConfigError("insensor_tensor is made by the sensor's ISP from its picture: it needs "
                              "insensor_input=isp and a network that takes a picture, not insensor_input=raw")

    @property
    def image_sent(self) -> bool:
        """False in metadata-only mode."""
        return self.output == "frame"

    def resolved_input(self, net: Network) -> str:
        """``raw`` or ``isp``: the configured input, checked against what the network takes."""
        want = self.input or net.input
        if self.tensor is not None and net.input == "raw":
            raise ConfigError(f"insensor={self.network!r} takes raw input; insensor_tensor needs a network that "
                              "takes a picture (insensor_input=isp)")
        if want != net.input:
            raise ConfigError(f"insensor={self.network!r} takes {net.input} input (a model trained with "
                              f"--input {'raw' if net.input == 'raw' else 'rgb'}), not insensor_input={want}")
        return want


INSENSOR_FIELDS = {"insensor_input": "input", "insensor_size": "max_size", "insensor_accel": "accel",
                   "insensor_output": "output", "insensor_roi": "roi", "insensor_tensor": "tensor"}
"""Option name -> ``InSensorConfig`` field."""
INSENSOR_OPTIONS = {"insensor", *INSENSOR_FIELDS}


def resolve_insensor(current: InSensorConfig | None, values: dict[str, Any]) -> InSensorConfig | None:
    """The in-sensor programming after ``values`` (parsed ``insensor*`` options) are applied to ``current``."""
    import dataclasses

    changes = {INSENSOR_FIELDS[k]: v for k, v in values.items() if k in INSENSOR_FIELDS}
    if "insensor" in values:
        if values["insensor"] is None:
            if changes:
                raise ConfigError(f"options {sorted(k for k in values if k != 'insensor')} need an in-sensor "
                                  "network (insensor=SPEC)")
            return None
        current = InSensorConfig(values["insensor"]) if current is None else \
            dataclasses.replace(current, network=values["insensor"])
    if not changes:
        return current
    if current is None:
        raise ConfigError(f"options {sorted(values)} need an in-sensor network (insensor=SPEC, e.g. "
                          "insensor=personnet-raw)")
    return dataclasses.replace(current, **changes)


def insensor_option_values(cfg: InSensorConfig | None) -> dict[str, Any]:
    """The ``insensor*`` options in effect."""
    c = cfg or InSensorConfig("none")
    return {"insensor": "none" if cfg is None else c.network, "insensor_input": c.input or "auto",
            "insensor_size": c.max_size, "insensor_accel": c.accel.name, "insensor_output": c.output,
            "insensor_roi": "none" if c.roi is None else ",".join(str(v) for v in c.roi),
            "insensor_tensor": "none" if c.tensor is None else c.tensor.to_text()}


# ----------------------------------------------------------------------------------------------- networks
@dataclass(frozen=True)
class NetworkOutput:
    """What one network run gives: boxes (N, 4) in its input image's pixels, scores, class ids, raw tensors."""

    boxes: Any
    scores: Any
    classes: Any
    tensors: tuple[tuple[str, Any], ...] = ()


class Network(Protocol):
    """An in-sensor network: ``input`` is ``raw`` (a mosaic of ``bits``-bit samples, H x W) or ``isp`` (8-bit
    BGR, H x W x 3); ``macs`` its multiply-accumulates per run at an input size; ``run`` one inference."""

    name: str
    input: str

    def macs(self, width: int, height: int) -> int:
        """Multiply-accumulates of one run on a ``width`` x ``height`` input."""
        ...

    def run(self, image: Any, bits: int) -> NetworkOutput:
        """One inference."""
        ...


Loader = Callable[[str], Network]
_loader: Loader | str | None = None
_cache: dict[str, Network] = {}
_cache_lock = threading.Lock()
MAX_NETWORKS = 8
"""Networks kept loaded at once (by spec text)."""


def set_network_loader(loader: Loader | str | None, replace: bool = True) -> None:
    """Register what turns a spec into a ``Network``: a callable, or ``"module:function"`` imported on first
    use (so registering costs no import); ``replace=False`` keeps a loader already registered. ``rollcam.host``
    registers its detectors' loader."""
    global _loader
    with _cache_lock:
        if _loader is not None and not replace:
            return
        _loader = loader
        _cache.clear()


def load_network(spec: str) -> Network:
    """The network of ``spec`` (loaded once and cached); ConfigError when it does not load or no loader is set."""
    with _cache_lock:
        net = _cache.get(spec)
        if net is not None:
            return net
        loader = _loader
        if loader is None:
            raise ConfigError(f"insensor={spec!r}: no network loader is registered (import rollcam.host, or call "
                              "rollcam.firmware.insensor.set_network_loader)")
        if isinstance(loader, str):
            module, _, name = loader.partition(":")
            loader = getattr(importlib.import_module(module), name)
        net = loader(spec)
        if len(_cache) >= MAX_NETWORKS:
            _cache.pop(next(iter(_cache)))
        _cache[spec] = net
        return net
