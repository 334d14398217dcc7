"""Clock.wait: every clock waits interruptibly, so loops never ask which clock they hold."""

from __future__ import annotations

import threading

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fabric.rate import Clock, FakeClock, MonotonicClock, RateLoop

waits = st.floats(min_value=-10.0, max_value=10.0, allow_nan=False)


@given(st.floats(min_value=-1e6, max_value=1e6, allow_nan=False), st.lists(waits, max_size=50))
def test_fake_wait_advances_by_each_wait_and_never_backwards(start, seq):
    clock = FakeClock(start)
    stop = threading.Event()
    expected = start
    for w in seq:
        before = clock.now()
        assert clock.wait(w, stop) is False
        expected += max(0.0, w)
        assert clock.now() >= before
        assert clock.now() == pytest.approx(expected, rel=1e-12, abs=1e-9)


@given(st.lists(waits, max_size=20))
def test_fake_wait_with_stop_set_returns_at_once_and_time_stands_still(seq):
    clock = FakeClock(5.0)
    stop = threading.Event()
    stop.set()
    for w in seq:
        assert clock.wait(w, stop) is True
    assert clock.now() == 5.0


def test_fake_wait_without_an_event_just_advances():
    clock = FakeClock()
    assert clock.wait(0.25) is False
    assert clock.now() == 0.25


class WaitOnlyClock:
    """A clock of the test's own: RateLoop must use its wait, whatever its class."""

    def __init__(self) -> None:
        self.t = 0.0
        self.waits: list[tuple[float, bool]] = []

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        raise AssertionError("RateLoop.run must wait on its stop event, not sleep")

    def wait(self, seconds: float, stop: threading.Event | None = None) -> bool:
        self.waits.append((seconds, stop is not None and stop.is_set()))
        self.t += seconds
        return stop is not None and stop.is_set()


def test_rate_loop_waits_through_any_clock_and_stops_when_told():
    clock: Clock = WaitOnlyClock()
    stop = threading.Event()
    ticks: list[float] = []

    def tick(now: float) -> None:
        ticks.append(now)
        if len(ticks) == 5:
            stop.set()

    RateLoop(10, tick, clock=clock).run(stop)
    assert ticks == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4])
    # every wait is handed the loop's stop event: the last one finds it set and ends the loop
    assert [w for w, _ in clock.waits] == pytest.approx([0.1] * 5)
    assert [set_ for _, set_ in clock.waits] == [False] * 4 + [True]


def test_rate_loop_on_a_fake_clock_keeps_its_grid():
    clock = FakeClock(3.0)
    stop = threading.Event()
    ticks: list[float] = []

    def tick(now: float) -> None:
        ticks.append(now)
        if len(ticks) == 20:
            stop.set()

    RateLoop(50, tick, clock=clock).run(stop)
    assert ticks == pytest.approx([3.0 + k * 0.02 for k in range(20)])


@pytest.mark.parametrize("spin_s", [0.0, 0.001])
def test_real_wait_is_cut_short_by_the_event(spin_s):
    clock = MonotonicClock(spin_s=spin_s)
    stop = threading.Event()
    result: list[bool] = []
    waiter = threading.Thread(target=lambda: result.append(clock.wait(60.0, stop)), daemon=True)
    t0 = clock.now()
    waiter.start()
    stop.set()
    waiter.join(30.0)
    assert not waiter.is_alive(), "a set event did not end a 60 s wait"
    assert result == [True]
    assert clock.now() - t0 < 60.0


@pytest.mark.parametrize("spin_s", [0.0, 0.0005, 0.05])
def test_real_wait_lasts_at_least_its_time_when_not_stopped(spin_s):
    clock = MonotonicClock(spin_s=spin_s)
    stop = threading.Event()
    t0 = clock.now()
    assert clock.wait(0.01, stop) is False
    assert clock.now() - t0 >= 0.01
    t0 = clock.now()
    assert clock.wait(0.005) is False
    assert clock.now() - t0 >= 0.005


def test_real_wait_with_the_event_already_set_returns_at_once():
    stop = threading.Event()
    stop.set()
    assert MonotonicClock().wait(60.0, stop) is True
    assert MonotonicClock(spin_s=120.0).wait(60.0, stop) is True


def test_negative_spin_is_refused():
    with pytest.raises(ValueError, match="spin"):
        MonotonicClock(spin_s=-1.0)
