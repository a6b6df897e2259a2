"""Emulated device interfaces on a ``rollcam.firmware.FirmwareCamera``.

``pump`` streams a camera in real time (row bands at their device times) to sinks; ``v4l2`` is a V4L2-like
device (raw constants, functions, ``Device``); ``http`` serves MJPEG and the live view over HTTP; ``serial_pty``
serves the control protocol on a pseudo-terminal and ``protocol_rollcam`` is pyserial's ``rollcam://`` URL handler.
"""
