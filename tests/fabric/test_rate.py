import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fabric.rate import FakeClock, RateLoop, parse_rates, phases, staggered


class SlowCallback:
    """Records tick times and, on chosen ticks, advances the fake clock as if the work took long."""

    def __init__(self, clock, costs=None):
        self.clock, self.costs, self.times = clock, costs or {}, []

    def __call__(self, now):
        self.times.append(now)
        self.clock.jump(self.costs.get(len(self.times), 0.0))


def test_ticks_land_on_absolute_grid_without_drift():
    clock = FakeClock(100.0)
    cb = SlowCallback(clock, {i: 0.003 for i in range(1, 1000)})  # each tick costs 3 ms of a 10 ms period
    loop = RateLoop(100, cb, clock=clock)
    while len(cb.times) < 500:
        clock.sleep(loop.step())
    assert cb.times[-1] == pytest.approx(100.0 + 499 * 0.01, abs=1e-9)
    assert loop.stats.overruns == 0


def test_overrun_is_counted_and_grid_skips_ahead_without_burst():
    clock = FakeClock()
    cb = SlowCallback(clock, {3: 0.035})  # tick 3 takes 3.5 periods
    loop = RateLoop(100, cb, clock=clock)
    while len(cb.times) < 8:
        clock.sleep(loop.step())
    assert loop.stats.overruns == 1
    assert loop.stats.skipped == 3
    gaps = [b - a for a, b in zip(cb.times, cb.times[1:])]
    assert min(gaps) >= 0.01 - 1e-9  # no catch-up burst
    assert cb.times[3] == pytest.approx(0.06)


def test_fake_clock_refuses_to_go_backwards():
    with pytest.raises(ValueError):
        FakeClock().jump(-1)


def test_rate_must_be_positive():
    with pytest.raises(ValueError):
        RateLoop(0, lambda now: None)


def test_parse_rates():
    d = {"joints": 100.0, "pose": 50.0, "scan": 20.0}
    assert parse_rates("joints=200, scan=10", d) == {"joints": 200.0, "pose": 50.0, "scan": 10.0}
    for bad in ("speed=3", "joints", "joints=fast", "joints=-1"):
        with pytest.raises(ValueError, match="bad rate"):
            parse_rates(bad, d)


def _threads(prefix: str) -> list[str]:
    import threading

    return [t.name for t in threading.enumerate() if t.name.startswith(prefix)]


def test_a_loop_runs_only_between_enter_and_exit():
    from robofabric.testing import wait_until

    ticks: list[float] = []
    loop = RateLoop(200, ticks.append, name="cm-test")
    assert not _threads("rate-cm-test") and loop.stats.ticks == 0  # building one starts nothing
    with loop as running:
        assert running is loop
        wait_until(lambda: len(ticks) >= 3, timeout=20, what="three ticks", seen=lambda: ticks)
    assert not _threads("rate-cm-test")  # leaving the with ended the thread
    after = len(ticks)
    assert loop.stats.ticks == after


def test_start_at_is_the_grid_origin_and_a_late_loop_joins_its_grid():
    """A loop given ``start_at`` ticks on ``start_at + k / hz`` only: before it, it waits for the origin; started
    after it (a thread that started late), its first tick is the grid's next one, not an overrun."""
    clock = FakeClock(100.0)
    early = SlowCallback(clock)
    loop = RateLoop(100, early, clock=clock, start_at=100.004)
    while len(early.times) < 3:
        clock.sleep(loop.step())
    assert early.times == pytest.approx([100.004, 100.014, 100.024], abs=1e-9)
    clock = FakeClock(100.0257)
    late = SlowCallback(clock)
    loop = RateLoop(100, late, clock=clock, start_at=100.0)
    while len(late.times) < 2:
        clock.sleep(loop.step())
    assert late.times == pytest.approx([100.03, 100.04], abs=1e-9)
    assert loop.stats.overruns == 0 and loop.stats.skipped == 0


@settings(deadline=None)  # a fake clock: the example's cost is its loop count, and a loaded CI host once took 0.3 s
@given(
    fastest=st.floats(min_value=5.0, max_value=1000.0),
    multiples=st.lists(st.integers(1, 8), min_size=1, max_size=5),
    delays=st.lists(st.floats(min_value=0.0, max_value=0.5), min_size=5, max_size=5),
)
def test_staggered_loops_on_one_origin_never_tick_together(fastest, multiples, delays):
    """Loops whose periods are whole multiples of the fastest, started on one origin with :func:`staggered`
    offsets (each thread starting when it does), tick at least 1/n of the fastest period apart, forever."""
    rates = {"fast": fastest, **{f"g{i}": fastest / m for i, m in enumerate(multiples)}}
    offsets = staggered(rates)
    ticks: dict[str, list[float]] = {}
    for (name, hz), delay in zip(rates.items(), delays + [0.0]):
        clock = FakeClock(10.0 + delay)
        cb = SlowCallback(clock)
        loop = RateLoop(hz, cb, clock=clock, start_at=10.0 + offsets[name])
        while len(cb.times) < 50:
            clock.sleep(loop.step())
        ticks[name] = cb.times
    gap = (1.0 / fastest) / len(rates)
    every = sorted((t, name) for name, ts in ticks.items() for t in ts)
    for (a, na), (b, nb) in zip(every, every[1:]):
        if na != nb:
            assert b - a >= gap - 1e-6, (na, a, nb, b)


def test_phases_deal_a_slower_loop_over_a_whole_divisor_of_its_period():
    """A sim's groups with 8 robots: scans over 5 phases, poses over 2; fewer robots than a whole divisor
    allows, or a period no whole multiple of the fastest, keep one phase."""
    rates = {"joints": 100.0, "pose": 50.0, "scan": 20.0}
    assert phases(rates, {"joints": 8, "pose": 8, "scan": 8}) == {"joints": 1, "pose": 2, "scan": 5}
    assert phases(rates, {"joints": 3, "pose": 3, "scan": 3}) == {"joints": 1, "pose": 2, "scan": 1}
    assert phases(rates, {"joints": 1, "pose": 1, "scan": 1}) == {"joints": 1, "pose": 1, "scan": 1}
    assert phases({"a": 100.0, "b": 30.0}, {"a": 9, "b": 9}) == {"a": 1, "b": 1}
    assert phases({"a": 100.0, "b": 12.5}, {"a": 9, "b": 6}) == {"a": 1, "b": 4}
    assert phases({}, {}) == {}


@settings(deadline=None)
@given(
    fastest=st.floats(min_value=5.0, max_value=1000.0),
    multiples=st.lists(st.integers(1, 12), min_size=1, max_size=5),
    members=st.lists(st.integers(0, 20), min_size=5, max_size=5),
)
def test_dealt_loops_stay_whole_multiples_of_the_fastest(fastest, multiples, members):
    """Every loop dealt over phases still ticks on a period that is a whole multiple of the fastest (so
    :func:`staggered` keeps the ticks apart), with no more phases than members, and each member keeps its rate."""
    rates = {"fast": fastest, **{f"g{i}": fastest / m for i, m in enumerate(multiples)}}
    count = {name: n for name, n in zip(rates, members + [1])}
    got = phases(rates, count)
    for name, hz in rates.items():
        k = got[name]
        assert 1 <= k <= max(1, count[name])
        loop_hz = hz * k
        ratio = fastest / loop_hz
        assert abs(ratio - round(ratio)) < 1e-6 and round(ratio) >= 1
