"""The emulator's HTTP door: the MJPEG stream, the JSON-lines endpoints and the live view, on one aiohttp host.

``server`` is the host and its limits, ``slots`` the fair slots of long-lived responses, ``mjpeg`` the MJPEG
stream (``MjpegServer``) with its ``faults``, ``jsonl`` the bounded JSON-lines mechanism behind ``imu`` and
``insensor``, and ``view`` the live page (``view_controls``, ``view_truth``; its script and style in ``web/``).
"""
