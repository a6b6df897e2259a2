"""The in-sensor network's results over HTTP: ``GET /insensor.jsonl``, one JSON object per result, as they are done.

Each line is an ``InSensorResult.to_json()`` (``seq`` of the frame it came from, its row timing, ``input_ns`` and
``done_ns`` on the device clock, ``detections`` as ``{box, score, cls}``, the output ``tensor_shapes``; with
``?tensors=1`` the tensors themselves); the first line is ``{"insensor": {...}}``, the network's programming,
with the stream's energy and bandwidth ledger (``rollcam.firmware.ledger``). A result is written once the
device clock has passed its ``done_ns``. ``?from_seq=N`` starts at frame N if it is still among the last
frames kept (default: the next result), ``?results=N`` ends the response after N results (default: endless).
It works in both output modes; in metadata-only mode (``insensor_output=meta``) it is the only thing the
camera sends. Bounded as every JSON-lines endpoint is (emu/http/jsonl.py).
"""

from __future__ import annotations

from typing import Any, ClassVar

from aiohttp import web
from rollcam.common.errors import DeviceError
from rollcam.common.values import non_negative_int, parse_bool
from rollcam.firmware.camera import FirmwareCamera

from .jsonl import JsonLinesStreams, query_option

INSENSOR_PATH = "/insensor.jsonl"


def programming(camera: FirmwareCamera) -> dict[str, Any]:
    """The first line: the in-sensor options in effect and the stream's ledger."""
    values = camera.spec.option_values()
    return {"insensor": {k: (list(v) if isinstance(v, tuple) else v) for k, v in values.items()
                         if k.startswith("insensor")}, "ledger": camera.insensor.ledger(camera.spec).to_json()}


class InSensorStreams(JsonLinesStreams):
    """The ``/insensor.jsonl`` handler of one camera, its readers held in fair slots (emu/http/jsonl.py)."""

    path: ClassVar[str] = INSENSOR_PATH
    what: ClassVar[str] = "in-sensor"
    limit_option: ClassVar[str] = "results"
    poll_s: ClassVar[float] = 0.01

    def open(self, request: web.Request) -> dict[str, Any]:
        """The stream's next frame: ``?from_seq`` or the one after the latest result done; ``?tensors``."""
        spec = getattr(self.camera, "spec", None)
        if spec is None or spec.insensor is None:
            raise web.HTTPNotFound(text="this camera has no in-sensor network (insensor=SPEC sets one)")
        start = query_option(request, "from_seq", non_negative_int)
        tensors = query_option(request, "tensors", parse_bool, False)
        cam = self.camera
        if start is None:  # from the next result done after now
            done = cam.insensor.recent(cam.clock_ns())
            start = done[-1].seq + 1 if done else 0
        return {"since": start, "tensors": tensors}

    def header(self) -> dict[str, Any]:
        """The network's programming and the stream's ledger."""
        return programming(self.camera)

    def take(self, cursor: dict[str, Any], most: int | None) -> list[dict[str, Any]]:
        """The results done since the cursor's frame (DeviceError once the network is turned off)."""
        cam = self.camera
        if cam.spec.insensor is None:
            raise DeviceError("the in-sensor network was turned off")
        fresh = cam.insensor.recent(cam.clock_ns(), cursor["since"])
        if most is not None:
            fresh = fresh[:most]
        if fresh:
            cursor["since"] = fresh[-1].seq + 1
        return [r.to_json(tensors=cursor["tensors"]) for r in fresh]
