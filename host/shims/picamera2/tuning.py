"""Camera tuning: what a Pi's ISP algorithms are tuned with (``Picamera2.load_tuning_file``), here described
for rollcam's ISP and accepted without effect, as the AE/AWB controls are.

On a Pi a tuning file (``imx477.json`` under libcamera's ``ipa/rpi/vc4``) sets up the ISP's algorithms. The
stand-in's ISP is fixed (black level, white balance gains, demosaic, sRGB), so ``load_tuning_file`` gives a
version-2 tuning that describes it (its contrast stage's gamma curve is the sRGB curve) with the algorithm
blocks scripts edit (``rpi.agc`` exposure modes, ``rpi.awb``, ``rpi.contrast``), and ``Picamera2(tuning=...)``
takes one and changes nothing.
"""

from __future__ import annotations

import copy
import json
import os
from typing import Any


def _srgb_curve(points: int = 33) -> list[int]:
    """The sRGB transfer curve as libcamera's gamma_curve: x0, y0, x1, y1, ... on 0..65535."""
    out = []
    for i in range(points):
        x = i / (points - 1)
        y = 12.92 * x if x <= 0.0031308 else 1.055 * x ** (1 / 2.4) - 0.055
        out += [round(x * 65535), round(min(max(y, 0.0), 1.0) * 65535)]
    return out


_TUNING: dict[str, Any] = {
    "version": 2.0,
    "target": "bcm2835",
    "algorithms": [
        {"rpi.black_level": {"black_level": 4096}},
        {"rpi.awb": {"bayes": 1, "ct_curve": [2850.0, 0.5, 0.5, 6500.0, 0.3, 0.3],
                     "modes": {"auto": {"lo": 2500, "hi": 8000}}}},
        {"rpi.agc": {"metering_modes": {"centre-weighted": {"weights": [3, 3, 3, 2, 2, 2, 2, 1, 1, 1, 1, 1, 0, 0, 0]}},
                     "exposure_modes": {"normal": {"shutter": [100, 10000, 30000, 60000, 66666],
                                                   "gain": [1.0, 2.0, 4.0, 6.0, 8.0]}},
                     "constraint_modes": {"normal": []}, "y_target": [0, 0.16, 1000, 0.165, 10000, 0.17]}},
        {"rpi.contrast": {"ce_enable": 0, "gamma_curve": _srgb_curve()}},
        {"rpi.ccm": {"ccms": [{"ct": 5000, "ccm": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]}]}},
    ],
}


def load_tuning_file(tuning_file: str, dir: str | None = None) -> dict[str, Any]:
    """The tuning in ``dir``/``tuning_file`` when that file exists, else the one describing rollcam's ISP."""
    if dir is not None and os.path.isfile(os.path.join(dir, tuning_file)):
        with open(os.path.join(dir, tuning_file)) as f:
            return json.load(f)
    return copy.deepcopy(_TUNING)


def find_tuning_algo(tuning: dict[str, Any], name: str) -> dict[str, Any]:
    """The parameters of algorithm ``name`` in a tuning (version 1: top-level keys; 2: the algorithms list)."""
    if tuning.get("version", 1) == 1:
        return tuning[name]
    return next(algo for algo in tuning["algorithms"] if name in algo)[name]
