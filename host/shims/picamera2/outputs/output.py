"""``Output``: where an encoder's frames go (picamera2's base class), and its timestamp file."""

from __future__ import annotations

import os
from typing import Any


class Output:
    """A destination for encoded frames: ``start()``, ``outputframe(frame, keyframe, timestamp)``, ``stop()``.

    ``pts``: a path (opened here) or a writable text file that gets one line per frame written, its timestamp
    in ms (``12.345``), counted from the recording's first frame on the device clock (the frame's
    ``SensorTimestamp``). As picamera2's, the file has no header line (mkvmerge's timestamp files start with
    ``# timestamp format v2``: a script writes it, as picamera2's examples do).
    """

    needs_add_stream = False

    def __init__(self, pts: Any = None) -> None:
        self.recording = False
        self.needs_pacing = False
        self.ptsoutput = pts
        self.stream: dict[str, Any] = {}  # what the encoder feeds: codec, width, height, rate

    @property
    def ptsoutput(self) -> Any:
        """The timestamp file (open), or None."""
        return self._ptsoutput

    @ptsoutput.setter
    def ptsoutput(self, file: Any) -> None:
        self._ptsoutput = open(file, "w") if isinstance(file, (str, os.PathLike)) else file  # noqa: SIM115

    def start(self) -> None:
        """Start taking frames."""
        self.recording = True

    def stop(self) -> None:
        """Stop taking frames."""
        self.recording = False

    def outputframe(self, frame: Any, keyframe: bool = True, timestamp: int | None = None, packet: Any = None,
                    audio: bool = False) -> None:
        """One encoded frame (``timestamp`` in us from the recording's first frame)."""

    def outputtimestamp(self, timestamp: int | None) -> None:
        """Add a frame's timestamp (us) to the timestamp file, in ms."""
        if self._ptsoutput is not None and timestamp is not None:
            print(f"{timestamp // 1000}.{timestamp % 1000:03d}", file=self._ptsoutput, flush=True)

    def _add_stream(self, encoder_stream: str, codec_name: str, **kwargs: Any) -> None:
        """The encoder says what it sends (``codec_name``: ``h264``, ``mjpeg``, ``rawvideo``; width, height,
        rate)."""
        self.stream = {"kind": encoder_stream, "codec": codec_name, **kwargs}
