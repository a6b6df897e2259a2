"""Ctrl-C as the tests deliver it: a plain KeyboardInterrupt, or as compiled code a SIGINT interrupts reports it
(numba: a SystemError raised from the KeyboardInterrupt); and to a child process, as a terminal sends it."""

from __future__ import annotations

import os
import signal
import subprocess


def ctrl_c(compiled: bool = False) -> None:
    """Raise Ctrl-C, the plain way or the compiled-code way."""
    if not compiled:
        raise KeyboardInterrupt
    try:
        raise KeyboardInterrupt
    except KeyboardInterrupt as exc:
        raise SystemError("returned a result with an exception set") from exc


def interrupt(proc: subprocess.Popen, timeout_s: float = 60, group: bool = False) -> tuple[str | bytes, str | bytes]:
    """Send Ctrl-C to a child (SIGINT to it, or with ``group`` to its whole process group, as a terminal does) and
    wait for it to exit: its (stdout, stderr). A child still running after ``timeout_s`` is killed and the test
    fails saying so."""
    if group:
        os.killpg(proc.pid, signal.SIGINT)
    else:
        proc.send_signal(signal.SIGINT)
    try:
        return proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        _out, err = proc.communicate()
        raise AssertionError(f"still running {timeout_s:g} s after Ctrl-C; stderr: {err!r}") from None
