"""The pure core of what a primary does after a freeze (sim_peer.replica.freeze_rule): publish again at once when nobody
could have taken over, else ask who holds the shard, after listening for a lease when the freeze outlasted it, and
then go on under a new term. Unit tests, then a property test over random freezes."""

from __future__ import annotations

from hypothesis import given, settings, strategies as hs

from sim_peer.replica import election as el
from sim_peer.replica import freeze_rule as fr
from sim_peer.replica import hearing_rule as hr

LEASE = 2.0


def test_a_freeze_with_no_other_sim_of_the_shard_publishes_again_at_once():
    assert fr.plan(5.0, LEASE, frozenset()) == fr.FreezePlan(publish_now=True)
    assert fr.rivals({"me"}, "me") == frozenset()


def test_a_short_freeze_with_a_rival_asks_at_once_and_keeps_its_term():
    assert fr.plan(1.5, LEASE, frozenset({"s"})) == fr.FreezePlan(publish_now=False, listen_s=0.0, reassert=False)


def test_a_freeze_longer_than_the_lease_listens_a_lease_then_asks_and_goes_on_under_a_new_term():
    assert fr.plan(3.0, LEASE, frozenset({"s"})) == fr.FreezePlan(
        publish_now=False, listen_s=LEASE + 0.5, reassert=True
    )


def test_the_rivals_are_the_shards_sims_alive_when_the_freeze_began_or_since():
    """A standby whose token went during the freeze could have taken over; one gone before it began could not;
    another shard's sim never could."""
    now, gap = 20.0, 3.0
    seen = hr.gone_since({"me", "b"}, {"early": 16.0, "during": 18.0}, fr.began(now, gap))
    shard = el.shard_view(seen, {"b": frozenset({"arm2"}), "during": frozenset({"arm1"})}, "me", frozenset({"arm1"}))
    assert fr.rivals(shard, "me") == {"during"}


def test_the_watch_gap_is_half_a_lease_and_the_ask_lasts_at_least_thirty_seconds():
    assert fr.watch_gap(LEASE) == 1.0
    assert fr.ask_for(1.0) == 30.0 and fr.ask_for(5.0) == 50.0


@settings(max_examples=150, deadline=None)
@given(hs.floats(0.0, 100.0), hs.floats(0.1, 20.0), hs.frozensets(hs.sampled_from(["a", "b", "me"])))
def test_property_a_freeze_is_muzzled_exactly_when_someone_could_have_taken_over(gap, lease, seen):
    """Publishing at once only with no rival; a freeze longer than the lease always listens longer than the lease
    (the new authority's streams reach us before we speak) and takes a new term; a shorter one neither."""
    rivals = fr.rivals(seen, "me")
    p = fr.plan(gap, lease, rivals)
    assert "me" not in rivals
    assert p.publish_now == (not rivals)
    if p.publish_now:
        assert p.listen_s == 0.0 and not p.reassert
    else:
        assert p.reassert == (gap > lease) and (p.listen_s > lease) == (gap > lease)
        assert p.listen_s == 0.0 or p.reassert
    assert fr.ask_for(fr.watch_gap(lease)) >= 30.0
