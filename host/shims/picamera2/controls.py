"""``Controls``: camera control changes gathered to be applied together, on one frame boundary.

Setting an attribute (``controls.ExposureTime = 10000``) records a change; the camera takes every recorded
change at once before its next frame starts, as libcamera delivers a request's controls. ``FrameRate`` is a
virtual control: it sets ``FrameDurationLimits`` (in us) from frames per second (one rate, or a (min, max)).
"""

from __future__ import annotations

import threading
from typing import Any


def _rates_to_durations(rates: Any) -> tuple[int, int]:
    lo, hi = rates if isinstance(rates, (tuple, list)) else (rates, rates)
    return (int(1_000_000 / hi), int(1_000_000 / lo))


def _durations_to_rates(durations: tuple[int, int]) -> float | tuple[float, float]:
    if durations[0] == durations[1]:
        return 1_000_000 / durations[0]
    return (1_000_000 / durations[1], 1_000_000 / durations[0])


_VIRTUAL = {"FrameRate": ("FrameDurationLimits", _rates_to_durations, _durations_to_rates)}


class Controls:
    """Control values by libcamera name, with the names that were set (``make_dict``); a name the camera
    does not advertise is a RuntimeError."""

    def __init__(self, picam2: Any, controls: dict[str, Any] | Controls | None = None) -> None:
        self._picam2 = picam2
        self._controls: set[str] = set()
        self._lock = threading.RLock()
        self.set_controls(controls or {})

    def __setattr__(self, name: str, value: Any) -> None:
        if not name.startswith("_"):
            if name in _VIRTUAL:
                real, to_real, _ = _VIRTUAL[name]
                name, value = real, to_real(value)
            known = getattr(self._picam2, "camera_controls", None)
            if known is not None and name not in known:
                raise RuntimeError(f"Control {name} is not advertised by libcamera")
            with self._lock:
                self._controls.add(name)
        self.__dict__[name] = value

    def __getattribute__(self, name: str) -> Any:
        if name in _VIRTUAL:
            real, _, to_virtual = _VIRTUAL[name]
            return to_virtual(object.__getattribute__(self, real))
        return object.__getattribute__(self, name)

    def __repr__(self) -> str:
        return f"<Controls: {self.make_dict()}>"

    def __enter__(self) -> Controls:
        self._lock.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self._lock.release()

    def set_controls(self, controls: dict[str, Any] | Controls) -> None:
        """Record several changes (a dict, or another Controls' recorded ones)."""
        with self._lock:
            if isinstance(controls, Controls):
                controls = controls.make_dict()
            if not isinstance(controls, dict):
                raise RuntimeError(f"Cannot update controls with {type(controls)} type")
            for k, v in controls.items():
                setattr(self, k, v)

    def make_dict(self) -> dict[str, Any]:
        """The recorded changes by name."""
        with self._lock:
            return {k: self.__dict__[k] for k in self._controls}

    def take(self) -> dict[str, Any]:
        """The recorded changes, forgetting them (the camera's side: what the next frame applies)."""
        with self._lock:
            out = self.make_dict()
            for k in self._controls:
                self.__dict__.pop(k, None)
            self._controls.clear()
            return out
