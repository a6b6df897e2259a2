"""Ctrl-C as the tests deliver it: a plain KeyboardInterrupt, or as compiled code a SIGINT interrupts reports it
(numba: a SystemError raised from the KeyboardInterrupt)."""

from __future__ import annotations


def ctrl_c(compiled: bool = False) -> None:
    """Raise Ctrl-C, the plain way or the compiled-code way."""
    if not compiled:
        raise KeyboardInterrupt
    try:
        raise KeyboardInterrupt
    except KeyboardInterrupt as exc:
        raise SystemError("returned a result with an exception set") from exc
