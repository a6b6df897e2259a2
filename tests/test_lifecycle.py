"""rollcam.common.lifecycle: the closeable base, the worker thread that keeps its error, the deadline."""

from __future__ import annotations

import threading

import pytest
from helpers import FakeClock
from rollcam.common.errors import DeviceError, SourceError
from rollcam.common.lifecycle import Closeable, Deadline, Stats, Worker


class Resource(Closeable):
    closed_error = SourceError

    def __init__(self, fail_on_enter: bool = False) -> None:
        self.released = 0
        self.fail_on_enter = fail_on_enter

    def _on_enter(self) -> None:
        if self.fail_on_enter:
            raise OSError("port in use")

    def _close(self) -> None:
        self.released += 1

    def use(self) -> str:
        self._check_open()
        return "ok"


def test_close_runs_once_whatever_calls_it():
    r = Resource()
    with r as got:
        assert got is r and not r.closed and r.use() == "ok"
    r.close()
    assert r.closed and r.released == 1
    with pytest.raises(SourceError, match="Resource is closed"):
        r.use()
    with pytest.raises(SourceError, match="closed"):
        r.__enter__()  # a closed object cannot be used again


def test_concurrent_closes_release_once():
    r = Resource()
    go = threading.Barrier(8)

    def close():
        go.wait()
        r.close()

    threads = [threading.Thread(target=close) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert r.released == 1


def test_a_failed_start_in_with_closes_before_raising():
    r = Resource(fail_on_enter=True)
    with pytest.raises(OSError, match="port in use"), r:
        pass
    assert r.closed and r.released == 1


def test_worker_keeps_its_error_and_reraises_it_wrapped_once():
    def boom():
        raise ZeroDivisionError("bad frame")

    w = Worker(boom, name="renderer", wrap=DeviceError).start()
    with pytest.raises(DeviceError):
        w.join(5)
    assert isinstance(w.error, ZeroDivisionError) and not w.alive
    with pytest.raises(DeviceError, match=r"renderer failed: ZeroDivisionError\('bad frame'\)") as info:
        w.check()
    assert isinstance(info.value.__cause__, ZeroDivisionError)
    w.close()  # the owner has seen it: closing does not raise it a second time
    assert w.closed


def test_worker_close_raises_an_error_nobody_saw_as_it_is():
    w = Worker(lambda: (_ for _ in ()).throw(KeyError("x")), name="reader").start()
    with pytest.raises(KeyError):
        w.close()
    w.close()  # closing twice is harmless


def test_worker_stops_on_its_event_and_joins():
    seen = []

    def loop(w_ref):
        while not w_ref[0].stop_event.wait(0.01):
            seen.append(1)

    ref: list[Worker] = []
    w = Worker(loop, ref, name="poller")
    ref.append(w)
    with w:
        assert w.alive
    assert w.stopping and not w.alive and w.error is None


def test_deadline_on_an_injected_clock():
    clock = FakeClock(100.0)
    d = Deadline(2.0, clock)
    assert not d.expired and d.remaining() == 2.0 and d.within(0.5) == 0.5
    clock.t += 1.5
    assert d.remaining() == pytest.approx(0.5) and d.within(5) == pytest.approx(0.5)
    clock.t += 1.0
    assert d.expired and d.remaining() == 0.0
    d.restart()
    assert not d.expired and d.remaining() == 2.0
    assert Deadline(0, clock).expired  # a zero timeout: a non-blocking attempt


def test_forever_never_expires():
    clock = FakeClock(100.0)
    for d in (Deadline.forever(clock), Deadline(None, clock), Deadline(float("inf"), clock)):
        clock.t += 1e9
        assert not d.expired and d.remaining() is None and d.within(0.2) == 0.2 and d.infinite
    with pytest.raises(ValueError, match="-1"):
        Deadline(-1)


def test_stats_to_json_is_a_copy():
    from dataclasses import dataclass

    @dataclass
    class Counts(Stats):
        frames: int = 0
        rt: str | None = None

    c = Counts()
    snap = c.to_json()
    c.frames += 1
    assert snap == {"frames": 0, "rt": None} and c.to_json()["frames"] == 1
