"""The emulated camera's own logic: register map, controls, serial control protocol, frame scheduler.

``FirmwareCamera`` (``camera``, with its stream half in ``stream``) is the device every source and transport
reads frames from; it holds a ``CameraSpec`` (``spec``: the one validated description of the camera, built
from the option table in ``options``). ``controls`` (the spec in the sensor's units and V4L2-named controls
with their side effects), ``registers`` (the hw_config register map with the part's
effects), ``traits`` (per-sensor register encodings), ``scheduler`` (device times of frames, lines and
bands), ``patterns`` (test patterns), ``imaging`` (pixels: BGR renders, or raw frames through the sensor model),
``pixfmt`` (the one place BGR renders become YUYV, MJPG, ...; raw formats and their preview),
``protocol`` (the line-based serial protocol), ``insensor`` and ``insensor_stage`` (a network run on the chip on
each frame, on the device clock) and ``ledger`` (bytes, link load and energy per frame). Nothing here knows of USB,
sockets or ptys.
"""
