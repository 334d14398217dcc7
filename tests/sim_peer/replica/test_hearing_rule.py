"""The pure core of whether a sim hears its world (sim_peer.replica.hearing_rule): its heartbeat's freezes and the distrust
after them, a cut, the wait after deafness and the audible sims, with the time passed in; then property tests over
random heartbeats."""

from __future__ import annotations

import math

from hypothesis import given, settings, strategies as hs

from sim_peer.replica import hearing_rule as hr

LEASE = 2.0
GAP = LEASE / 2


def beat_at(*ticks: float, connected: bool = True) -> hr.Heartbeat:
    """A heartbeat that ticked at each of ``ticks`` (the first one: join)."""
    beat = hr.Heartbeat(last_tick=ticks[0])
    for t in ticks[1:]:
        beat = hr.tick(beat, t, gap=GAP, connected=connected)
    return beat


def test_a_regular_heartbeat_is_never_frozen_and_a_sim_not_joined_is_not_either():
    assert not hr.frozen(hr.Heartbeat(), 100.0, LEASE)
    beat = beat_at(*(10 + 0.1 * i for i in range(50)))
    assert beat.thawed_at == -math.inf and not hr.frozen(beat, beat.last_tick + 0.05, LEASE)


def test_a_late_heartbeat_is_frozen_now_and_a_freeze_is_distrusted_a_lease_and_as_long_again():
    beat = beat_at(10.0, 10.1)
    assert hr.frozen(beat, 10.1 + GAP + 0.01, LEASE)  # late right now: its next tick has not come
    beat = hr.tick(beat, 13.1, gap=GAP, connected=True)  # back from a 3 s freeze
    assert (beat.thawed_at, beat.late_s) == (13.1, 3.0)
    for t in (13.1 + 0.5 * i for i in range(1, 10)):  # ticking on regularly, still distrusted (up to 17.6)
        beat = hr.tick(beat, t, gap=GAP, connected=True)
        assert hr.frozen(beat, t, LEASE)
    assert hr.frozen(beat, 13.1 + LEASE + 3.0 - 0.01, LEASE)
    beat = hr.tick(beat, 13.1 + LEASE + 3.0 + 0.01, gap=GAP, connected=True)  # a lease and 3 s after the thaw
    assert beat.thawed_at == 13.1 and not hr.frozen(beat, beat.last_tick, LEASE)


def test_the_log_says_a_freeze_is_a_freeze_late_now_or_lately():
    beat = beat_at(10.0, 10.1)
    assert hr.freeze_words(beat, 10.2, LEASE) == ""  # on time: not frozen, nothing to say
    assert hr.freeze_words(beat, 11.6, LEASE) == "frozen: its heartbeat is 1.5 s late"
    beat = hr.tick(beat, 13.1, gap=GAP, connected=True)  # back from a 3 s freeze
    assert hr.freeze_words(beat, 14.1, LEASE) == "frozen: its heartbeat came 3.0 s late 1.0 s ago"


def test_a_freeze_longer_than_five_leases_is_distrusted_for_six_leases_only():
    beat = beat_at(0.0, 60.0, *(60.0 + 0.5 * i for i in range(1, 24)))  # on time again up to 71.5
    assert beat.late_s == 60.0 and beat.thawed_at == 60.0
    assert hr.frozen(beat, beat.last_tick, LEASE)
    beat = hr.tick(beat, 72.5 + 0.01 - 0.5, gap=GAP, connected=True)
    beat = hr.tick(beat, 72.5 + 0.01, gap=GAP, connected=True)
    assert not hr.frozen(beat, beat.last_tick, LEASE)


def test_a_tick_that_finds_the_link_down_marks_when_and_a_lost_token_then_went_with_the_link():
    beat = beat_at(5.0, 5.1, connected=False)
    assert beat.unlinked_at == 5.1 and hr.recently_unlinked(beat, 5.2)
    assert not hr.recently_unlinked(beat, 5.1 + 2 * hr.TICK_S)
    assert hr.unlinked_since(beat, -math.inf, lost_at=5.2)  # the link went a tick before the token
    assert not hr.unlinked_since(beat, -math.inf, lost_at=5.1 + 2 * hr.TICK_S + 0.01)
    assert hr.unlinked_since(hr.Heartbeat(), own_gone_at=7.0, lost_at=7.1)  # our own token went with it


def test_a_cut_is_the_link_down_or_our_own_token_gone_for_a_while():
    assert hr.cut(connected=False, own_token_seen=True, own_gone_at=-math.inf, now=1.0) == "its link is down"
    assert hr.cut(connected=True, own_token_seen=True, own_gone_at=0.5, now=1.0) == ""
    assert (
        hr.cut(connected=True, own_token_seen=False, own_gone_at=0.5, now=1.0) == "the router no longer holds its token"
    )
    assert hr.cut(connected=True, own_token_seen=False, own_gone_at=0.5, now=0.5 + hr.OWN_TOKEN_S + 0.1) == ""


def test_the_wait_after_deafness_starts_when_it_hears_and_again_after_a_new_cut():
    window = hr.recheck_window(LEASE)
    assert window == hr.RECHECK_LEASES * LEASE + 0.5
    back = hr.recheck(hr.NOT_YET, 1.0, deaf=True, window=window)
    assert back == hr.NOT_YET
    back = hr.recheck(back, 2.0, deaf=False, window=window)
    assert back == 2.0 + window
    assert hr.recheck(back, 3.0, deaf=False, window=window) == back  # the window set does not move
    assert hr.recheck(back, 3.0, deaf=True, window=window) == hr.NOT_YET  # cut again: it starts over


def test_the_audible_sims_count_only_while_the_view_is_fresh_or_a_missing_leader_is_relooked_at():
    heard = {"p": 10.0, "q": 10.0 - hr.AUDIBLE_S - 0.1}
    assert hr.audible(heard, 10.5, fresh_until=11.0, relooking=False) == {"p"}
    assert hr.audible(heard, 10.5, fresh_until=10.0, relooking=False) == frozenset()
    assert hr.audible(heard, 10.5, fresh_until=10.0, relooking=True) == {"p"}
    assert hr.audible(heard, 10.0 + hr.AUDIBLE_S, fresh_until=math.inf, relooking=False) == frozenset()


def test_a_leader_heard_whose_token_was_never_seen_stays_audible_after_the_fresh_view():
    heard = {"p": 10.0, "q": 10.0}
    assert hr.audible(heard, 10.5, fresh_until=10.0, relooking=False, unseen=("p",)) == {"p"}  # only the unseen one
    assert hr.audible(heard, 10.0 + hr.AUDIBLE_S, fresh_until=10.0, relooking=False, unseen=("p",)) == frozenset()
    assert hr.audible(heard, 10.5, fresh_until=10.0, relooking=False, unseen=("r",)) == frozenset()  # never heard


@given(
    hs.dictionaries(hs.sampled_from("pqrs"), hs.floats(0.0, 10.0)),
    hs.floats(0.0, 12.0),
    hs.floats(0.0, 12.0),
    hs.booleans(),
    hs.sets(hs.sampled_from("pqrs")),
)
def test_the_audible_sims_were_heard_just_now_and_after_the_fresh_view_are_unseen_ones(
    heard, now, fresh_until, relooking, unseen
):
    got = hr.audible(heard, now, fresh_until=fresh_until, relooking=relooking, unseen=unseen)
    assert got <= {p for p, t in heard.items() if now - t < hr.AUDIBLE_S}
    if now > fresh_until and not relooking:
        assert got <= unseen
    else:
        assert got == hr.audible(heard, now, fresh_until=fresh_until, relooking=relooking)


def test_the_sims_alive_or_gone_since_a_freeze_began():
    assert hr.gone_since({"a"}, {"b": 4.0, "c": 6.0}, began=5.0) == {"a", "c"}


intervals = hs.lists(hs.tuples(hs.floats(0.01, 6 * LEASE), hs.booleans()), min_size=1, max_size=40)


@settings(max_examples=200, deadline=None)
@given(intervals)
def test_property_the_distrust_after_a_freeze_begins_at_once_and_ends_within_six_leases(steps):
    """Any heartbeat: a tick after a gap longer than half a lease is frozen at once; a tick more than six leases
    after the last freeze, on time, is not; a heartbeat whose gaps are all short is never frozen; the link down is
    marked at the last tick that found it down."""
    now, beat = 0.0, hr.Heartbeat(last_tick=0.0)
    last_freeze, last_down = -math.inf, -math.inf
    for dt, connected in steps:
        before, now = now, now + dt
        beat = hr.tick(beat, now, gap=GAP, connected=connected)
        if now - before > GAP:
            last_freeze = now
            assert beat.thawed_at == now and beat.late_s == now - before
            assert hr.frozen(beat, now, LEASE)
        if not connected:
            last_down = now
        assert beat.unlinked_at == last_down and beat.last_tick == now
        if now - last_freeze > 6 * LEASE:
            assert not hr.frozen(beat, now, LEASE)
        assert hr.frozen(beat, now + GAP + 0.01, LEASE)  # the next tick late: frozen now, whatever came before
    if last_freeze == -math.inf:
        assert beat.thawed_at == -math.inf


@settings(max_examples=200, deadline=None)
@given(hs.lists(hs.tuples(hs.floats(0.01, 3.0), hs.booleans()), min_size=1, max_size=60), hs.floats(0.5, 5.0))
def test_property_the_wait_after_deafness_ends_only_after_a_whole_window_of_hearing(looks, window):
    """Looks at random times, deaf or not: whenever the wait is over, the last ``window`` seconds held no deaf
    look, and a deaf look always starts it over."""
    now, back, last_deaf = 0.0, hr.NOT_YET, 0.0
    for dt, deaf in looks:
        now += dt
        back = hr.recheck(back, now, deaf=deaf, window=window)
        if deaf:
            last_deaf = now
            assert back == hr.NOT_YET
        if now >= back:
            assert now - last_deaf >= window
