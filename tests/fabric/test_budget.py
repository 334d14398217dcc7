"""Property tests of the per-login token bucket (fabric.budget): what one login may spend, and no more."""

from __future__ import annotations

import pytest
from hypothesis import given, settings, strategies as hs

from fabric.budget import RATE_LIMITED, Budgets, Bucket, Rate, take

rates = hs.builds(Rate, hs.floats(0.1, 1000.0), hs.floats(1.0, 200.0))
gaps = hs.lists(hs.floats(0.0, 2.0), min_size=1, max_size=200)


@given(rates, gaps)
def test_tokens_stay_between_zero_and_burst(rate, steps):
    bucket, now = None, 0.0
    for dt in steps:
        now += dt
        bucket, _ = take(bucket, rate, now)
        assert 0.0 <= bucket.tokens <= rate.burst


@given(rates, gaps)
def test_never_more_than_burst_plus_rate_times_elapsed(rate, steps):
    """Over any run of asks, those allowed are at most the burst plus what the rate refilled meanwhile."""
    bucket, now, allowed = None, 0.0, 0
    for dt in steps:
        now += dt
        bucket, ok = take(bucket, rate, now)
        allowed += ok
    assert allowed <= rate.burst + rate.per_s * now + 1e-6


@given(rates, hs.integers(1, 500))
def test_a_flood_at_one_instant_gets_the_burst_only(rate, n):
    bucket, allowed = None, 0
    for _ in range(n):
        bucket, ok = take(bucket, rate, 5.0)
        allowed += ok
    assert allowed == min(n, int(rate.burst))


@given(rates, hs.integers(1, 300))
def test_quiet_for_burst_over_rate_gives_the_whole_burst_back(rate, n):
    bucket = None
    for _ in range(n):
        bucket, _ = take(bucket, rate, 0.0)
    later = rate.burst / rate.per_s + 1e-6
    bucket, ok = take(bucket, rate, later)
    assert ok and bucket.tokens == pytest.approx(rate.burst - 1)


@given(rates, hs.floats(0.0, 100.0), hs.floats(0.0, 100.0))
def test_time_going_back_gives_nothing(rate, t1, back):
    bucket = Bucket(0.0, t1)
    after, ok = take(bucket, rate, t1 - back)
    assert not ok and after.tokens == 0.0 and after.at == t1


@settings(max_examples=50)
@given(rates, hs.integers(1, 300))
def test_one_logins_flood_leaves_anothers_budget_whole(rate, n):
    budgets = Budgets(rate)
    for _ in range(n):
        budgets.allow("mallory", 1.0)
    assert all(budgets.allow("bob", 1.0) for _ in range(int(rate.burst)))
    assert budgets.refused["bob"] == 0
    assert budgets.refused["mallory"] == max(0, n - int(rate.burst))


def test_made_up_logins_are_bounded():
    budgets = Budgets(Rate(1.0, 2.0), max_logins=8)
    for i in range(8):
        assert budgets.allow(f"u{i}", 0.0)
    assert not budgets.allow("ninth", 0.0)  # none has filled up again: a new name waits
    assert budgets.refused[""] == 1
    assert budgets.allow("ninth", 10.0)  # the old ones are full again and forgotten
    assert len(budgets._buckets) == 1


def test_rate_parses_and_refuses_nonsense():
    assert Rate.parse("5/10") == Rate(5.0, 10.0)
    assert Rate.parse("3") == Rate(3.0, 6.0)
    for bad in ("", "x", "0", "-1/2", "5/0", "inf"):
        with pytest.raises(ValueError):
            Rate.parse(bad)
    assert Budgets(Rate(1, 1)).refusal("mallory", "requests").startswith(RATE_LIMITED + ": mallory")
