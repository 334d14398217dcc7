"""Property tests of the pure ownership state machine over random event sequences."""

from __future__ import annotations

import pytest
from hypothesis import example, given, settings, strategies as hs

from ownership import state as st

USERS = ["a", "b", "c", "d"]
OBJECTS = {"arm": "exclusive", "base": "exclusive", "ball": "scene"}
LEASE, GRACE = 2.0, 10.0


def events():
    user = hs.sampled_from(USERS)
    obj = hs.sampled_from(sorted(OBJECTS))
    dt = hs.floats(0.0, 3.0)
    return hs.lists(
        hs.one_of(
            hs.tuples(hs.just("join"), user, dt),
            hs.tuples(hs.just("leave"), user, dt),
            hs.tuples(hs.just("request"), user, obj, hs.booleans(), dt),
            hs.tuples(hs.just("release"), user, obj, dt),
            hs.tuples(hs.just("renew"), user, obj, dt),
            hs.tuples(hs.just("tick"), dt, hs.booleans()),
            hs.tuples(hs.just("motion"), obj, hs.booleans()),
        ),
        max_size=60,
    )


def build(raw, now):
    kind = raw[0]
    if kind == "join":
        return st.Join(raw[1], now)
    if kind == "leave":
        return st.Leave(raw[1], now)
    if kind == "request":
        return st.Request(raw[1], raw[2], now, raw[3])
    if kind == "release":
        return st.Release(raw[1], raw[2], now)
    if kind == "renew":
        return st.Renew(raw[1], raw[2], now)
    if kind == "tick":
        return st.Tick(now, relinked=len(raw) > 2 and raw[2])
    return st.Motion(raw[1], raw[2])


def check_invariants(s: st.OwnState) -> None:
    assert set(s.held) <= s.live, (
        f"held users {set(s.held) - s.live} are not live"
    )  # held: her token's loss not taken yet
    for obj, rec in s.records.items():
        if rec.policy == "scene":
            assert rec.owner == "" and rec.queue == ()
            continue
        if rec.owner:
            assert rec.owner in s.live, f"{obj}: owner {rec.owner} is not live"
            assert rec.owner not in rec.queue
        assert len(set(rec.queue)) == len(rec.queue)
        ranks = [s.rank[u] for u in rec.queue]
        assert ranks == sorted(ranks), f"{obj}: queue {rec.queue} out of join order"
        assert all(u in s.live for u in rec.queue)


@settings(max_examples=300, deadline=None)
@given(events())
@example(
    [
        ("join", "c", 0.0),
        ("leave", "c", 0.0),
        ("tick", 1.0),
        ("join", "a", 3.0),
        ("join", "a", 3.0),
        ("join", "a", 3.0),
        ("request", "a", "arm", False, 0.0),
        ("request", "c", "arm", False, 0.0),
        ("tick", 1.0),
        ("request", "c", "arm", True, 0.0),
    ]
)  # asked while away: her rank outlived her grace
@example(
    [
        ("request", "c", "arm", False, 0.0),
        ("join", "a", 2.0),
        ("join", "a", 3.0),
        ("join", "a", 3.0),
        ("request", "a", "arm", False, 0.0),
        ("request", "c", "arm", True, 1.0),
        ("join", "a", 1.0),
        ("tick", 1.0),
    ]
)  # one tick: a's lease ends, the arm passes to c, c's tokenless grace ends too
def test_invariants_over_random_sequences(seq):
    s = st.initial(OBJECTS, lease_s=LEASE, grace_s=GRACE)
    now = 0.0
    for raw in seq:
        now += raw[-1] if raw[0] not in ("motion",) and isinstance(raw[-1], float) else 0.0
        before = s
        ev = build(raw, now)
        s, effects = st.step(s, ev)
        check_invariants(s)
        for obj in OBJECTS:
            a, b = before.records[obj], s.records[obj]
            assert b.epoch >= a.epoch
            if a.owner != b.owner:
                assert b.epoch > a.epoch, f"{obj}: owner changed {a.owner!r}->{b.owner!r} without a new epoch"
            # a robot moves only while a live owner drives it: losing its owner stops it, and nothing else does
            stops = [e for e in effects if e.kind == "stop" and e.object == obj]
            if a.owner and a.owner != b.owner:  # (one step may also hand it on and take it back: a stop each)
                assert stops and stops[0].user == a.owner and stops[0].reason, (
                    f"{obj}: {a.owner} lost it without a stop"
                )
            else:
                assert not stops, f"{obj}: stopped while {a.owner!r} kept it: {stops}"
        if isinstance(
            ev, st.Request
        ):  # a flood of requests moves no epoch: refused, queued or already hers, none is new
            answer = next(
                e
                for e in effects
                if e.user == ev.user and e.object == ev.object and e.kind in ("granted", "denied", "queued")
            )
            if answer.kind != "granted" or before.records[ev.object].owner == ev.user:
                assert s.records[ev.object].epoch == before.records[ev.object].epoch, f"{answer}: epoch moved"
        if (
            isinstance(ev, st.Request)
            and OBJECTS[ev.object] == "exclusive"
            and before.records[ev.object].owner not in ("", ev.user)
            and ev.user in before.live
            and ev.user not in before.unproven
        ):
            rec = before.records[ev.object]
            if rec.state == "moving":
                assert s.records[ev.object].owner == rec.owner, "a moving robot was handed over on request"
            else:
                assert s.records[ev.object].owner == ev.user, "a still robot was not handed over"


def test_moving_robot_is_not_handed_over_until_released():
    s = st.initial({"arm": "exclusive"})
    s, _ = st.step(s, st.Join("a", 0.0))
    s, _ = st.step(s, st.Join("b", 0.0))
    s, eff = st.step(s, st.Request("a", "arm", 0.0))
    assert eff[0].kind == "granted" and s.records["arm"].owner == "a"
    s, _ = st.step(s, st.Motion("arm", True))
    s, eff = st.step(s, st.Request("b", "arm", 0.1))
    assert eff[0].kind == "denied" and "in motion" in eff[0].reason and "owned by a" in eff[0].reason
    s, eff = st.step(s, st.Request("b", "arm", 0.1, wait=True))
    assert (eff[0].kind, eff[0].position) == ("queued", 1)
    e1 = s.records["arm"].epoch
    s, eff = st.step(s, st.Release("a", "arm", 0.2))
    assert s.records["arm"].owner == "b" and s.records["arm"].epoch == e1 + 1
    assert s.records["arm"].state == "moving"  # nothing resets on handover


def test_still_robot_is_handed_over():
    s = st.initial({"arm": "exclusive"})
    s, _ = st.step(s, st.Request("a", "arm", 0.0))
    s, _ = st.step(s, st.Join("b", 0.2))
    s, eff = st.step(s, st.Request("b", "arm", 0.5))
    assert s.records["arm"].owner == "b" and [e.kind for e in eff] == ["granted", "revoked", "stop"]
    assert (eff[2].user, eff[2].reason) == ("a", "taken over by b from a")


def test_a_user_without_a_token_takes_a_free_robot_but_never_someones():
    s = st.initial({"arm": "exclusive"}, lease_s=100.0)
    s, eff = st.step(s, st.Request("a", "arm", 0.0))  # free: granted before a's token arrives
    assert eff[0].kind == "granted"
    s, eff = st.step(s, st.Request("ghost", "arm", 0.5))
    assert s.records["arm"].owner == "a" and eff[0].kind == "denied" and "no liveliness token" in eff[0].reason
    s, eff = st.step(s, st.Request("ghost", "arm", 0.5, wait=True))
    assert eff[0].kind == "queued" and s.records["arm"].queue == ("ghost",)
    s, _ = st.step(s, st.Join("ghost", 0.6))
    s, eff = st.step(s, st.Request("ghost", "arm", 0.7))
    assert s.records["arm"].owner == "ghost"


def test_lease_expiry_passes_to_next_in_join_order():
    s = st.initial({"arm": "exclusive"}, lease_s=1.0)
    for u in ("a", "c", "b"):
        s, _ = st.step(s, st.Join(u, 0.0))
    s, _ = st.step(s, st.Request("a", "arm", 0.0))
    s, _ = st.step(s, st.Motion("arm", True))
    s, _ = st.step(s, st.Request("b", "arm", 0.1, wait=True))
    s, _ = st.step(s, st.Request("c", "arm", 0.2, wait=True))
    assert s.records["arm"].queue == ("c", "b")  # join order, not request order
    s, _ = st.step(s, st.Renew("a", "arm", 0.5))
    for t in (0.9, 1.3):  # the authority hears others (a waiting user's renewal is denied, but heard)
        s, _ = st.step(s, st.Renew("b", "arm", t))
    s, _ = st.step(s, st.Tick(1.4))
    assert s.records["arm"].owner == "a"
    s, eff = st.step(s, st.Tick(1.6))
    assert s.records["arm"].owner == "c" and s.records["arm"].queue == ("b",)
    assert ("expired", "a", "lease of arm (a) expired: no renewal for 1.1 s") in [
        (e.kind, e.user, e.reason) for e in eff
    ]


def _owned_by_a(lease: float = 2.0) -> st.OwnState:
    s = st.initial({"arm": "exclusive", "base": "exclusive"}, lease_s=lease)
    for u in ("a", "b"):
        s, _ = st.step(s, st.Join(u, 0.0))
    s, _ = st.step(s, st.Request("a", "arm", 0.0))
    s, _ = st.step(s, st.Request("b", "base", 0.0))
    s, _ = st.step(s, st.Tick(0.0))
    return s


def test_a_paused_authority_extends_leases_instead_of_expiring_them():
    """The authority's ticks stop for 10 s (SIGSTOP, a starved process): when it runs again, every owner
    has a whole lease to renew, although every lease ran out long ago by the clock."""
    s = _owned_by_a()
    s, eff = st.step(s, st.Tick(10.0))
    assert not eff and s.records["arm"].owner == "a" and s.records["base"].owner == "b"
    s, _ = st.step(s, st.Renew("b", "base", 10.3))  # renewals sent during the pause arrive, b's first
    s, eff = st.step(s, st.Tick(10.4))
    assert not eff and s.records["arm"].owner == "a"
    s, _ = st.step(s, st.Renew("a", "arm", 10.5))
    for t in (11.0, 11.5, 12.0, 12.5):
        s, _ = st.step(s, st.Renew("b", "base", t))
        s, eff = st.step(s, st.Tick(t))
    assert not eff and s.records["arm"].owner == "a" and s.records["arm"].epoch == 1


def test_an_authority_whose_own_link_came_back_gives_every_owner_a_whole_lease_from_then():
    """Its link lost and back within a tick (a starved sim, 0.0 s), others heard all along: renewals sent to the old
    link are lost, so no lease ends within a lease of the link's return, and one still not renewed then ends."""
    s = _owned_by_a()
    for t in (0.5, 1.0, 1.5):  # b renews; a's renewals go with the old link
        s, _ = st.step(s, st.Renew("b", "base", t))
        s, eff = st.step(s, st.Tick(t, relinked=t == 1.5))
        assert not eff
    for t in (2.0, 2.5, 3.0, 3.45):  # a's lease ran out at 2.0, but the link was back at 1.5
        s, _ = st.step(s, st.Renew("b", "base", t))
        s, eff = st.step(s, st.Tick(t))
        assert not eff and s.records["arm"].owner == "a", t
    s, _ = st.step(s, st.Renew("b", "base", 3.55))
    s, eff = st.step(s, st.Tick(3.55))
    assert ("expired", "arm") in [(e.kind, e.object) for e in eff]


def test_without_its_link_changing_an_owner_who_stops_renewing_loses_the_robot_at_her_leases_end():
    s = _owned_by_a()
    for t in (0.5, 1.0, 1.5, 2.05):
        s, _ = st.step(s, st.Renew("b", "base", t))
        s, eff = st.step(s, st.Tick(t))
    assert ("expired", "arm") in [(e.kind, e.object) for e in eff]


def test_an_authority_that_hears_nobody_expires_no_lease():
    """Nothing from any user for 5 s while the ticks run (a stalled router, a lost link): no lease ends.
    Once users are heard again, an owner who still does not renew loses the robot a lease later."""
    s = _owned_by_a()
    for i in range(1, 51):
        s, eff = st.step(s, st.Tick(i * 0.1))
        assert not eff, (i, eff)
    s, _ = st.step(s, st.Renew("b", "base", 5.0))  # b is heard again; a never is
    for t in (5.5, 6.0, 6.5):
        s, _ = st.step(s, st.Renew("b", "base", t))
        s, eff = st.step(s, st.Tick(t))
        assert not eff and s.records["arm"].owner == "a"
    s, _ = st.step(s, st.Renew("b", "base", 7.0))
    s, eff = st.step(s, st.Tick(7.05))
    assert [(e.kind, e.object) for e in eff] == [("released", "arm"), ("stop", "arm"), ("expired", "arm")]
    assert "no renewal for 7.0 s" in eff[2].reason and s.records["base"].owner == "b"


def test_an_owner_who_stops_renewing_while_others_are_heard_loses_the_robot():
    s = _owned_by_a()
    for i in range(1, 30):
        s, _ = st.step(s, st.Renew("b", "base", i * 0.1))
        s, eff = st.step(s, st.Tick(i * 0.1))
        if eff:
            break
    assert [(e.kind, e.user) for e in eff] == [
        ("released", "a"),
        ("stop", "a"),
        ("expired", "a"),
    ] and 2.0 < i * 0.1 <= 2.2


@settings(max_examples=300, deadline=None)
@given(events())
def test_no_lease_expires_when_the_authority_heard_nothing_since_the_owners_last_word(seq):
    """Whatever happened before: a tick that follows the owner's last request or renewal with nothing
    heard from any user in between (a pause, a backlog, a stalled router) never expires that lease."""
    s = st.initial(OBJECTS, lease_s=LEASE, grace_s=GRACE)
    now = 0.0
    last_heard = float("-inf")
    for raw in seq:
        now += raw[-1] if raw[0] not in ("motion",) and isinstance(raw[-1], float) else 0.0
        ev = build(raw, now)
        before = s
        s, effects = st.step(s, ev)
        if isinstance(ev, st.Tick):
            for e in effects:
                if e.kind == "expired":
                    assert last_heard > before.records[e.object].lease_expiry - LEASE, (e, last_heard)
        elif not isinstance(ev, (st.Leave, st.Motion)):
            last_heard = now


def test_reconnect_within_grace_restores_queue_place():
    s = st.initial({"arm": "exclusive"}, grace_s=10.0)
    for u in ("a", "b", "c"):
        s, _ = st.step(s, st.Join(u, 0.0))
    s, _ = st.step(s, st.Request("a", "arm", 0.0))
    s, _ = st.step(s, st.Motion("arm", True))
    s, _ = st.step(s, st.Request("c", "arm", 0.0, wait=True))
    s, _ = st.step(s, st.Request("b", "arm", 0.0, wait=True))
    s, _ = st.step(s, st.Renew("a", "arm", 0.5))  # the owner renews as her client does: the authority hears all along
    s, _ = st.step(s, st.Leave("b", 1.0))
    assert s.records["arm"].queue == ("c",)
    for i in range(2, 10):
        s, _ = st.step(s, st.Renew("a", "arm", i * 0.5))
    s, eff = st.step(s, st.Join("b", 5.0))
    assert s.records["arm"].queue == ("b", "c")
    assert eff[0].kind == "restored" and eff[0].position == 1
    # the owner leaves: ownership passes on; it comes back in grace: queued at its old (first) place
    s, _ = st.step(s, st.Renew("a", "arm", 5.5))
    s, _ = st.step(s, st.Leave("a", 6.0))
    assert s.records["arm"].owner == "b"
    s, _ = st.step(s, st.Join("a", 7.0))
    assert s.records["arm"].queue == ("a", "c")


def test_reconnect_after_grace_is_a_new_join():
    s = st.initial({"arm": "exclusive"}, grace_s=1.0)
    for u in ("a", "b", "c"):
        s, _ = st.step(s, st.Join(u, 0.0))
    s, _ = st.step(s, st.Request("c", "arm", 0.0))
    s, _ = st.step(s, st.Motion("arm", True))
    s, _ = st.step(s, st.Request("a", "arm", 0.0, wait=True))
    s, _ = st.step(s, st.Request("b", "arm", 0.0, wait=True))
    s, _ = st.step(s, st.Leave("a", 0.5))
    s, _ = st.step(s, st.Tick(2.0))
    s, _ = st.step(s, st.Join("a", 2.1))
    assert s.records["arm"].queue == ("b",)
    s, _ = st.step(s, st.Request("a", "arm", 2.2, wait=True))
    assert s.records["arm"].queue == ("b", "a")


def test_owner_alone_leaves_and_returns_as_owner():
    s = st.initial({"arm": "exclusive"})
    s, _ = st.step(s, st.Request("a", "arm", 0.0))
    s, _ = st.step(s, st.Leave("a", 1.0))
    assert s.records["arm"].owner == ""
    e = s.records["arm"].epoch
    s, _ = st.step(s, st.Join("a", 2.0))
    assert s.records["arm"].owner == "a" and s.records["arm"].epoch == e + 1


def test_a_requester_without_a_token_leaves_queue_and_robot_after_grace():
    s = st.initial({"arm": "exclusive"}, lease_s=100.0, grace_s=5.0)
    s, _ = st.step(s, st.Join("a", 0.0))
    s, _ = st.step(s, st.Request("a", "arm", 0.0))
    s, _ = st.step(s, st.Motion("arm", True))
    s, eff = st.step(s, st.Request("ghost", "arm", 1.0, wait=True))  # never declares a token
    s, _ = st.step(s, st.Request("b", "arm", 1.0, wait=True))
    s, _ = st.step(s, st.Join("b", 2.0))  # b's token arrives late, within grace: b stays
    assert eff[0].kind == "queued" and s.records["arm"].queue == ("ghost", "b")
    s, _ = st.step(s, st.Tick(5.9))
    assert s.records["arm"].queue == ("ghost", "b")
    s, eff = st.step(s, st.Tick(6.1))
    assert s.records["arm"].queue == ("b",) and "ghost" not in s.rank and "ghost" not in s.live
    assert [(e.kind, e.user) for e in eff] == [("released", "ghost")]
    assert not s.unproven


def test_a_tokenless_owner_loses_the_robot_after_grace():
    s = st.initial({"arm": "exclusive"}, lease_s=100.0, grace_s=5.0)
    s, _ = st.step(s, st.Request("ghost", "arm", 0.0))
    s, _ = st.step(s, st.Renew("ghost", "arm", 4.0))
    s, _ = st.step(s, st.Tick(5.5))
    assert s.records["arm"].owner == "" and s.records["arm"].epoch == 2


def test_the_queue_is_capped():
    from fabric.interfaces import MAX_QUEUE

    s = st.initial({"arm": "exclusive"})
    s, _ = st.step(s, st.Join("owner", 0.0))
    s, _ = st.step(s, st.Request("owner", "arm", 0.0))
    s, _ = st.step(s, st.Motion("arm", True))
    for i in range(MAX_QUEUE):
        s, _ = st.step(s, st.Join(f"u{i}", 0.0))
        s, eff = st.step(s, st.Request(f"u{i}", "arm", 0.0, wait=True))
        assert eff[0].kind == "queued"
    s, eff = st.step(s, st.Request("late", "arm", 0.0, wait=True))
    assert eff[0].kind == "denied" and "queue is full" in eff[0].reason and len(s.records["arm"].queue) == MAX_QUEUE
    s, eff = st.step(s, st.Request("u3", "arm", 0.0, wait=True))  # already waiting: asking again is fine
    assert eff[0].kind == "queued"


def test_tokenless_requesters_are_capped_and_one_more_costs_no_copy():
    """A flood of forged names (no liveliness token) holds at most MAX_UNPROVEN of them; each request
    past the cap is refused with the state untouched (the same object: nothing copied), so the work per
    request stays the same however long the flood (20k forged requests took ~28 s before the cap)."""
    s = st.initial({"arm": "exclusive"}, lease_s=100.0, grace_s=5.0)
    s, _ = st.step(s, st.Join("alice", 0.0))
    s, _ = st.step(s, st.Request("alice", "arm", 0.0))
    for i in range(st.MAX_UNPROVEN + 300):
        before = s
        s, eff = st.step(s, st.Request(f"fake{i}", "arm", 1.0, wait=i % 2 == 0))
        if i >= st.MAX_UNPROVEN:
            assert (
                s is before
                and eff[0].kind == "denied"
                and "too many requesters without a liveliness token" in eff[0].reason
            )
    assert len(s.unproven) == st.MAX_UNPROVEN
    assert len(s.rank) == len(s.live) == st.MAX_UNPROVEN + 1  # rank: live users and away ones, never more
    assert s.records["arm"].owner == "alice"
    s, _ = st.step(s, st.Join("bob", 2.0))  # a user with a token is not turned away by the flood
    s, eff = st.step(s, st.Request("bob", "arm", 2.0))
    assert eff[0].kind == "granted" and s.records["arm"].owner == "bob"
    s, _ = st.step(s, st.Tick(6.5))  # grace over: the fakes are gone, and a new requester is heard again
    assert not s.unproven and set(s.rank) == set(s.live) == {"alice", "bob"}
    s, eff = st.step(s, st.Request("late", "arm", 7.0, wait=True))
    assert eff[0].kind == "queued" and "late" in s.unproven


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(events())
def test_nothing_is_kept_about_tokenless_users_once_grace_is_over(seq):
    s = st.initial(OBJECTS, lease_s=LEASE, grace_s=GRACE)
    now = 0.0
    joined = set()
    for raw in seq:
        now += raw[-1] if raw[0] not in ("motion",) and isinstance(raw[-1], float) else 0.0
        if raw[0] == "join":
            joined.add(raw[1])
        s, _ = st.step(s, build(raw, now))
    s, _ = st.step(s, st.Tick(now + GRACE + 1.0))
    check_invariants(s)
    assert not s.unproven
    for rec in s.records.values():
        assert set(rec.queue) <= joined and rec.owner in joined | {""}


def test_an_owner_whose_renewal_is_back_before_her_token_gets_her_robot_back():
    """A router restart closes every link: the authority sees alice's token go and frees her arm, and
    her renewal can come back before her token does. It proves she is there (as a request does): she is
    owner again under a newer epoch, as her token's return would make her. Past grace, or once someone
    else took the arm, the renewal is denied as before."""
    s = st.initial({"arm": "exclusive"}, lease_s=2.0, grace_s=10.0)
    s, _ = st.step(s, st.Join("alice", 0.0))
    s, _ = st.step(s, st.Request("alice", "arm", 0.0))
    e1 = s.records["arm"].epoch
    s, _ = st.step(s, st.Leave("alice", 1.0))
    assert s.records["arm"].owner == "" and "alice" in s.away
    back, eff = st.step(s, st.Renew("alice", "arm", 2.0))
    assert [(e.kind, e.user) for e in eff] == [("restored", "alice")]
    assert back.records["arm"].owner == "alice" and back.records["arm"].epoch > e1 + 1
    check_invariants(back)
    back, eff = st.step(back, st.Join("alice", 2.5))  # her token follows: nothing changes hands again
    assert back.records["arm"].owner == "alice" and not eff and not back.unproven and "alice" not in back.away
    # too late: grace is over
    late, eff = st.step(s, st.Renew("alice", "arm", 11.5))
    assert late.records["arm"].owner == "" and eff[0].kind == "denied"
    # someone else took the free arm meanwhile
    s2, _ = st.step(s, st.Join("bob", 1.5))
    s2, _ = st.step(s2, st.Request("bob", "arm", 1.5))
    taken, eff = st.step(s2, st.Renew("alice", "arm", 2.0))
    assert taken.records["arm"].owner == "bob" and eff[0].kind == "denied"
    # a user who never held it is not given it by renewing
    s3, _ = st.step(s, st.Join("carol", 1.5))
    s3, eff = st.step(s3, st.Renew("carol", "arm", 2.0))
    assert s3.records["arm"].owner == "" and eff[0].kind == "denied"


def test_an_owner_away_while_someone_else_used_her_robot_does_not_get_it_back():
    """bench lab: alice's cable is pulled, her token goes and her arm passes to bob, who was queued; bob moves it
    and releases it; alice comes back within grace. She must not be made owner again as if nothing happened
    (her program would command an arm someone else moved): neither her renewal nor her token's return restores
    her, and she reads the newer free record as a loss."""
    s = st.initial({"arm": "exclusive"}, lease_s=2.0, grace_s=10.0)
    for u in ("alice", "bob"):
        s, _ = st.step(s, st.Join(u, 0.0))
    s, _ = st.step(s, st.Request("alice", "arm", 0.0))
    s, _ = st.step(s, st.Motion("arm", True))
    s, _ = st.step(s, st.Request("bob", "arm", 0.1, wait=True))
    s, _ = st.step(s, st.Leave("alice", 2.0))
    assert s.records["arm"].owner == "bob"
    s, _ = st.step(s, st.Motion("arm", False))
    s, _ = st.step(s, st.Release("bob", "arm", 4.0))
    assert s.records["arm"].owner == ""
    check_invariants(s)
    renewed, eff = st.step(s, st.Renew("alice", "arm", 5.0))
    assert renewed.records["arm"].owner == "" and [e.kind for e in eff] == ["denied"]
    joined, eff = st.step(s, st.Join("alice", 5.0))
    assert joined.records["arm"].owner == "" and not [e for e in eff if e.kind == "restored"]
    check_invariants(joined)


def _records(s: st.OwnState) -> dict:
    return {o: (r.owner, r.epoch, r.queue) for o, r in s.records.items()}


def test_a_token_lost_while_the_authority_is_deaf_is_held_and_nothing_changes_when_it_returns():
    """A router stalled by 20,000 declarations (or paused 8 s) cuts its clients' links, and bob's token goes as it
    comes back; his base is neither released nor restored (no epoch 5 -> 7). His token lost while
    nobody was heard (alice's renewals overdue too) holds him: no record changes, his lease does not run
    out while he reconnects, and his token's return changes nothing."""
    s = _owned_by_a()  # a owns arm, b owns base
    for t in (0.5, 1.0):
        s, _ = st.step(s, st.Renew("a", "arm", t))
        s, _ = st.step(s, st.Renew("b", "base", t))
    for i in range(11, 90):  # the router stalls for 8 s: ticks run, nobody is heard
        s, eff = st.step(s, st.Tick(i * 0.1))
        assert not eff, (i, eff)
    before = _records(s)
    s, eff = st.step(s, st.Leave("b", 9.0))  # the router comes back and closes the links it let expire
    assert not eff and st.hearing_in_doubt(s, 9.0, "b") and "b" in s.held
    t = 9.0
    while t < 13.0:  # alice renews again at once; bob reconnects 4 s later (zenoh's retry)
        t += 0.1
        s, _ = st.step(s, st.Renew("a", "arm", t))
        s, eff = st.step(s, st.Tick(t))
        assert not eff and _records(s) == before, (t, eff)
    s, eff = st.step(s, st.Leave("a", 11.0))  # alice's token goes a moment later too (within grace of hearing again)
    assert not eff and "a" in s.held
    s, eff = st.step(s, st.Join("b", 13.0))
    s2, eff2 = st.step(s, st.Join("a", 13.0))
    assert not eff and not eff2 and _records(s2) == before and not s2.held
    s2, eff = st.step(s2, st.Renew("b", "base", 13.1))
    assert [e.kind for e in eff] == ["renewed"] and s2.records["base"].epoch == before["base"][1]


def test_a_held_user_whose_token_does_not_return_within_grace_leaves():
    s = _owned_by_a()
    for i in range(1, 90):  # nobody heard for 9 s
        s, _ = st.step(s, st.Tick(i * 0.1))
    s, eff = st.step(s, st.Leave("b", 9.0))
    assert not eff and "b" in s.held
    t, eff = 9.0, []
    while not eff:
        t += 0.1
        s, _ = st.step(s, st.Renew("a", "arm", t))
        s, eff = st.step(s, st.Tick(t))
    assert t > 9.0 + GRACE and [(e.kind, e.object, e.user) for e in eff][:2] == [
        ("released", "base", "b"),
        ("stop", "base", "b"),
    ]
    assert eff[0].reason == "left" and not s.held and "b" not in s.live and s.records["arm"].owner == "a"


def test_an_owner_alone_cut_off_is_not_held():
    """Her cable pulled: her renewals stop and her token goes a transport lease later, with nobody else to hear:
    that is no doubt about the authority's hearing, and the robot passes to the next in the queue at once."""
    s = st.initial({"arm": "exclusive"}, lease_s=2.0, grace_s=10.0)
    for u in ("alice", "bob"):
        s, _ = st.step(s, st.Join(u, 0.0))
    s, _ = st.step(s, st.Request("alice", "arm", 0.0))
    s, _ = st.step(s, st.Motion("arm", True))
    s, _ = st.step(s, st.Request("bob", "arm", 0.1, wait=True))
    s, _ = st.step(s, st.Renew("alice", "arm", 0.5))
    s, eff = st.step(s, st.Leave("alice", 2.5))
    assert s.records["arm"].owner == "bob" and eff[0].kind == "handover" and not s.held


@settings(max_examples=300, deadline=None)
@given(events(), hs.sampled_from(USERS), hs.lists(hs.floats(0.0, 0.3), max_size=8), hs.floats(0.0, 1.0))
def test_a_token_lost_and_back_while_hearing_is_in_doubt_changes_no_record(seq, user, ticks, back):
    """Whatever happened before: after the authority's own pause (a late tick), a user's token going and coming
    back within grace, with time passing in between, changes no record (owner, epoch, queue) of any object."""
    s = st.initial(OBJECTS, lease_s=LEASE, grace_s=GRACE)
    now = 0.0
    for raw in seq:
        now += raw[-1] if raw[0] not in ("motion",) and isinstance(raw[-1], float) else 0.0
        s, _ = st.step(s, build(raw, now))
    s, _ = st.step(s, st.Tick(now))
    now += 5.0
    s, _ = st.step(s, st.Tick(now))  # the authority was paused (or starved) for 5 s
    if user not in s.live or user in s.held or user in s.away or any(d <= now + 4.0 for d in s.unproven.values()):
        # (a requester without a token whose grace ends meanwhile leaves on her own; one away who asked again before
        # her token came back gets her robots back when it does: other rules. Hypothesis found the second in a run)
        return
    before = _records(s)
    now += 0.1
    assert st.hearing_in_doubt(s, now, user)
    s, eff = st.step(s, st.Leave(user, now))
    assert not eff and _records(s) == before
    for dt in ticks:
        now += dt
        s, eff = st.step(s, st.Tick(now))
        assert not [e for e in eff if e.object and any(e.user == u for u in (user,))], eff
    s, eff = st.step(s, st.Join(user, now + back))
    assert not eff and user not in s.held
    changed = {o: (before[o], r) for o, r in _records(s).items() if r != before[o]}
    assert not changed, changed
    check_invariants(s)
