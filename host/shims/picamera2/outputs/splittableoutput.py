"""``SplittableOutput``: frames passed on to one output, switched to another at a keyframe without losing
any (``split_output``)."""

from __future__ import annotations

import threading
from typing import Any

from .output import Output


class SplittableOutput(Output):
    """Passes frames to ``output`` (drops them without one); ``split_output(new)`` moves to ``new`` at the
    next keyframe (at once with ``wait_for_keyframe=False``), then stops the old one."""

    def __init__(self, output: Output | None = None, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._output = output
        self._new_output: Output | None = None
        self._wait_for_keyframe = True
        self._split_done = threading.Event()
        self._streams: list[tuple[str, str, dict[str, Any]]] = []

    def split_output(self, new_output: Output, wait_for_keyframe: bool = True) -> None:
        """Switch to ``new_output``; returns once the switch is made and the old output stopped."""
        old = self._output
        new_output.start()
        for encoder_stream, codec, kwargs in self._streams:
            new_output._add_stream(encoder_stream, codec, **kwargs)
        self._wait_for_keyframe = wait_for_keyframe
        self._new_output = new_output
        self._split_done.wait()
        self._split_done.clear()
        if old is not None:
            old.stop()

    def outputframe(self, frame: Any, keyframe: bool = True, timestamp: int | None = None, packet: Any = None,
                    audio: bool = False) -> None:
        """Pass the frame on (to the new output from a keyframe on, once a split is asked for)."""
        if self._new_output is not None and (not self._wait_for_keyframe or (keyframe and not audio)):
            self._output, self._new_output = self._new_output, None
            self._split_done.set()
        if self._output is not None:
            self._output.outputframe(frame, keyframe, timestamp, packet, audio)

    def start(self) -> None:
        """Start, and start the output."""
        super().start()
        if self._output is not None:
            self._output.start()

    def stop(self) -> None:
        """Stop, and stop the output."""
        super().stop()
        if self._output is not None:
            self._output.stop()

    def _add_stream(self, encoder_stream: str, codec_name: str, **kwargs: Any) -> None:
        self._streams.append((encoder_stream, codec_name, kwargs))
        if self._output is not None:
            self._output._add_stream(encoder_stream, codec_name, **kwargs)
