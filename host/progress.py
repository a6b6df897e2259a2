"""The one progress line every command shows on stderr while it works (tqdm underneath).

Off when stderr is not a terminal (logs and pipes get no carriage-return noise), unless a command's
``--progress`` asks for it. A count with a known total shows done/total, rate and ETA; a long job without
one (a benchmark's steps) shows its current step as the line's text, refreshed in place.
"""

from __future__ import annotations

import sys
from typing import TextIO

from tqdm import tqdm


def _isatty(stream: TextIO) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False


class Progress:
    """One refreshing line: ``update(done)`` moves the count, ``status(text)`` names the current step."""

    def __init__(self, total: int | None = None, *, label: str, stream: TextIO | None = None,
                 enabled: bool | None = None, unit: str = "it", min_interval_s: float = 0.1) -> None:
        self.total, self.label = total, label
        self.stream = sys.stderr if stream is None else stream
        self.enabled = _isatty(self.stream) if enabled is None else bool(enabled)
        # The bar format has no bar glyphs: it is read in logs as often as on terminals.
        fmt = ("{desc} {n_fmt}/{total_fmt}  {rate_fmt}  ETA {remaining}{postfix}" if total is not None
               else "{desc} [{elapsed}]{postfix}")
        self._bar = tqdm(total=total, desc=label, file=self.stream, disable=not self.enabled, unit=f" {unit}",
                         mininterval=min_interval_s, bar_format=fmt, dynamic_ncols=True, leave=True)

    def update(self, done: int) -> None:
        """Show ``done`` of ``total`` (refreshed at most every ``min_interval_s``, always at the end)."""
        if self.enabled and done != self._bar.n:
            self._bar.update(done - self._bar.n)

    def status(self, text: str, refresh: bool = True) -> None:
        """Name the step the work is on (the text after the count); ``refresh=False`` leaves it for the next
        ``update`` to show (a per-frame status would otherwise redraw the line every frame)."""
        if self.enabled:
            self._bar.set_postfix_str(text, refresh=refresh)

    def close(self) -> None:
        """End the line so later output starts on a fresh one; safe to call twice."""
        self._bar.close()
