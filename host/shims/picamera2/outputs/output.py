"""``Output``: where an encoder's frames go (picamera2's base class), and its timestamp file."""

from __future__ import annotations

import os
from typing import Any


class Output:
    """A destination for encoded frames: ``start()``, ``outputframe(frame, keyframe, timestamp)``, ``stop()``.

    ``pts``: a path (or writable text file) that gets one line per frame written, its timestamp in ms
    (``# timecode format v2``, as mkvmerge reads), counted from the recording's first frame on the device
    clock (the frame's ``SensorTimestamp``).
    """

    needs_add_stream = False

    def __init__(self, pts: Any = None) -> None:
        self.recording = False
        self.ptsoutput = pts
        self._pts_file: Any = None
        self.stream: dict[str, Any] = {}  # what the encoder feeds: codec, width, height, rate

    def start(self) -> None:
        """Start taking frames (and open the timestamp file)."""
        if isinstance(self.ptsoutput, (str, os.PathLike)):
            self._pts_file = open(self.ptsoutput, "w")  # noqa: SIM115 (open until stop)
        elif self.ptsoutput is not None:
            self._pts_file = self.ptsoutput
        if self._pts_file is not None:
            print("# timecode format v2", file=self._pts_file, flush=True)
        self.recording = True

    def stop(self) -> None:
        """Stop taking frames (and close a timestamp file this output opened)."""
        self.recording = False
        if self._pts_file is not None and isinstance(self.ptsoutput, (str, os.PathLike)):
            self._pts_file.close()
        self._pts_file = None

    def outputframe(self, frame: Any, keyframe: bool = True, timestamp: int | None = None, packet: Any = None,
                    audio: bool = False) -> None:
        """One encoded frame (``timestamp`` in us from the recording's first frame)."""
        self.outputtimestamp(timestamp)

    def outputtimestamp(self, timestamp: int | None) -> None:
        """Add a frame's timestamp (us) to the timestamp file, in ms."""
        if self._pts_file is not None and self.recording and timestamp is not None:
            print(f"{timestamp // 1000}.{timestamp % 1000:03d}", file=self._pts_file, flush=True)

    def _add_stream(self, encoder_stream: str, codec_name: str, **kwargs: Any) -> None:
        """The encoder says what it sends (``codec_name``: ``h264``, ``mjpeg``, ``rawvideo``; width, height,
        rate)."""
        self.stream = {"kind": encoder_stream, "codec": codec_name, **kwargs}
