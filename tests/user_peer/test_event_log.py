"""A user's event log (user_peer.event_log): only an event from its object's authority, on a key only sims write,
may refuse her commands; everything else is shown as display-only and counted. Pure: sims and records are given."""

from __future__ import annotations

from fabric import keys
from fabric.interfaces import Event, Header, OwnershipRecord
from user_peer.event_log import KEPT, EventLog

W = "w"


def _log(records: dict[str, OwnershipRecord], live=("sim-a", "sim-b")):
    seen: list[str] = []
    log = EventLog(
        "alice", live_sim=lambda peer: peer in live, record=records.get, then=lambda key, ev: seen.append(key)
    )
    return log, seen


def _reject(source: str, user: str = "alice", obj: str = "arm1") -> Event:
    return Event(kind="reject", object=obj, user=user, reason="not_owner", header=Header(source=source))


def test_only_the_objects_live_authority_on_a_sim_key_can_refuse():
    log, seen = _log({"arm1": OwnershipRecord("arm1", owner="bob", epoch=3, authority="sim-a")})
    mark = log.mark()
    sim_key = keys.event(W, "reject", "arm1")
    log.receive(sim_key, _reject("sim-a"))  # the authority itself: trusted
    log.receive(sim_key, _reject("sim-b"))  # a live sim, not arm1's authority
    log.receive(sim_key, _reject("sim-x"))  # no live sim of this world
    log.receive(keys.event_decode(W, "mallory"), _reject("sim-a"))  # any login may write this key
    log.receive(sim_key, _reject("sim-a", user="bob"))  # trusted, but another user's refusal
    assert [e.header.source for e in log.rejections("arm1", mark)] == ["sim-a"]
    assert [trusted for _, trusted in log.recent()] == [True, False, False, False, True]
    assert log.untrusted == 3 and log.mark() == mark + 5 and len(seen) == 5


def test_without_a_record_any_live_sim_is_believed_and_marks_divide_before_from_after():
    log, _ = _log({})
    key = keys.event(W, "reject", "arm1")
    log.receive(key, _reject("sim-b"))
    mark = log.mark()
    assert log.rejections("arm1", mark) == []
    log.receive(key, _reject("sim-a"))
    assert [e.header.source for e in log.rejections("arm1", mark)] == ["sim-a"]
    assert log.rejections("arm2", 0) == []


def test_the_log_is_bounded_and_keeps_counting():
    log, _ = _log({})
    key = keys.event(W, "clamp", "arm1")
    for i in range(KEPT + 1):
        log.receive(key, Event(kind="clamp", object="arm1", reason=str(i), header=Header(source="sim-a")))
    assert len(log.events) == KEPT + 1 - KEPT // 2 and log.events[-1].reason == str(KEPT)
    assert log.mark() == KEPT + 1 and [e.reason for e, _ in log.recent(2)] == [str(KEPT - 1), str(KEPT)]


def test_authority_events_of_a_kind_are_read_once_from_mark_to_mark_and_never_forged():
    log, _ = _log({"base1": OwnershipRecord("base1", owner="bob", epoch=1, authority="sim-a")})
    bump = lambda src: Event(kind="collision", object="base1", reason="bumper", header=Header(source=src))  # noqa: E731
    key = keys.event(W, "collision", "base1")
    first = log.mark()
    log.receive(key, bump("sim-a"))  # no user named: a bumper stop concerns whoever watches
    log.receive(key, bump("sim-b"))  # not base1's authority
    log.receive(keys.event_decode(W, "mallory"), bump("sim-a"))  # any login may write this key
    log.receive(keys.event(W, "clamp", "base1"), Event(kind="clamp", object="base1", header=Header(source="sim-a")))
    second = log.mark()
    log.receive(key, bump("sim-a"))  # after the second mark: the next reading's
    assert [e.kind for e in log.authority_events(first, second, frozenset({"collision"}))] == ["collision"]
    assert len(log.authority_events(second, log.mark(), frozenset({"collision"}))) == 1
    assert [e.kind for e in log.authority_events(first, log.mark(), frozenset({"clamp", "collision"}))] == [
        "collision",
        "clamp",
        "collision",
    ]
