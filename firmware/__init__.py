"""The emulated camera's own logic: register map, controls, serial control protocol, frame scheduler.

``FirmwareCamera`` (``camera``) is the device every transport sits on: ``controls`` (programmable state and
V4L2-named controls with their side effects), ``registers`` (the hw_config register map with the part's
effects), ``traits`` (per-sensor register encodings), ``scheduler`` (device times of frames, lines and
bands), ``patterns`` (test patterns), ``imaging`` (pixels: BGR renders, or raw frames through the sensor model),
``pixfmt`` (the formats it offers: the ISP's processed ones and the sensor's raw ones),
``scene`` (scene controls) and ``protocol`` (the line-based serial protocol). Nothing here knows of USB,
sockets or ptys.
"""
