"""Pacing with an injected clock: real time, X times real time, as fast as possible, and falling behind."""

from __future__ import annotations

import pytest

from fabric.rate import FakeClock
from sim_peer.physics.pacing import Pacer, parse_speed


def test_parse_speed():
    assert parse_speed("1") == 1.0 and parse_speed("12.5") == 12.5 and parse_speed(None) == 1.0
    assert parse_speed("max") is None and parse_speed("MAX") is None
    for bad in ("0", "-2", "fast", "nan", "1e400x"):
        with pytest.raises(ValueError, match="positive number or 'max'"):
            parse_speed(bad)


@pytest.mark.parametrize("speed", [1.0, 10.0, 0.5])
def test_steps_follow_the_clock_times_the_speed(speed):
    clock = FakeClock()
    p = Pacer(0.002, speed, clock=clock)
    assert p.due() == 0
    total = 0
    for _ in range(100):
        clock.jump(0.01)
        n = p.due()
        p.done(n)
        total += n
    assert total == pytest.approx(1.0 * speed / 0.002, abs=1)
    assert p.due() == 0 and 0 < p.wait() <= 0.002 / speed + 1e-12


def test_max_speed_always_has_a_chunk():
    p = Pacer(0.002, None, clock=FakeClock(), chunk=50)
    assert p.due() == 50 and p.wait() == 0.0


def test_falling_behind_drops_time_instead_of_bursting():
    clock = FakeClock()
    p = Pacer(0.002, 1.0, clock=clock, max_lag=0.25)
    p.due()
    clock.jump(5.0)  # the process was frozen for 5 s
    n = p.due()
    assert n == 125 and p.dropped == 2500 - 125
    p.done(n)
    assert p.due() == 0


@pytest.mark.parametrize("speed", [1.0, 0.5, 4.0])
def test_a_wake_up_takes_its_chunk_of_steps_and_no_step_is_lost(speed):
    """``wake_s``: steps come in chunks of at least 10 ms of wall time, and over a second all of them come."""
    clock = FakeClock()
    p = Pacer(0.002, speed, clock=clock, wake_s=0.01)
    batch = int(0.01 * speed / 0.002)
    assert p.batch == batch and p.due() == 0
    chunks: list[int] = []
    for _ in range(1000):
        clock.jump(0.001)
        n = p.due()
        if n:
            chunks.append(n)
            p.done(n)
            assert p.wait() == pytest.approx(batch * 0.002 / speed, abs=1e-9)  # the next chunk's whole wait
    assert min(chunks) >= batch and max(chunks) <= batch + 1
    assert sum(chunks) == pytest.approx(1.0 * speed / 0.002, abs=batch)
