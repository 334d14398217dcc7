"""Lease renewals (:class:`ownership.renewal.Renewal`): a renewal whose answer never comes holds nothing up."""

from __future__ import annotations

import threading

from fabric.interfaces import OwnershipRecord, OwnReply
from ownership.renewal import LATE_ROUND_S, MAX_IN_FLIGHT, STUCK_ROUNDS, Renewal
from robofabric.testing import wait_until


def _reply(obj: str) -> OwnReply:
    return OwnReply("renewed", "", 0, OwnershipRecord(obj, owner="alice", epoch=1))


def test_a_renewal_left_unanswered_is_sent_again_after_two_rounds_and_the_other_robot_renews_on():
    """arm1's first renewal never answers (a lost reply): arm1 is renewed again STUCK_ROUNDS rounds later, never
    more than MAX_IN_FLIGHT at once, while base1 is renewed every round."""
    asked: list[tuple[str, float]] = []
    release = threading.Event()
    now = [0.0]

    def ask(obj: str) -> OwnReply:
        asked.append((obj, now[0]))
        if obj == "arm1":
            release.wait(10.0)  # no answer until the test lets it go
        return _reply(obj)

    r = Renewal("alice", ask, dict, renew_s=0.01, clock=lambda: now[0])
    r.hold("arm1")
    r.hold("base1")
    turns = [(round(t, 2), r._take_turn("arm1", t)) for t in (0.0, 0.01, 0.019, 0.02, 0.04, 0.06, 0.08)]
    # the first, then one STUCK_ROUNDS rounds after the last sent, up to MAX_IN_FLIGHT
    assert [t for t, took in turns if took] == [0.0, 0.02, 0.04][:MAX_IN_FLIGHT], turns
    assert STUCK_ROUNDS == 2 and r.in_flight("arm1") == MAX_IN_FLIGHT
    release.set()


def test_rounds_on_a_real_clock_renew_a_robot_whose_first_answer_is_lost():
    asked: list[str] = []
    hang = threading.Event()

    def ask(obj: str) -> OwnReply:
        asked.append(obj)
        if obj == "arm1" and asked.count("arm1") == 1:
            hang.wait(10.0)  # the first renewal of arm1: its answer lost (until the end of the test)
        return _reply(obj)

    r = Renewal("alice", ask, dict, renew_s=0.05)
    r.hold("arm1")
    r.hold("base1")
    r.start()
    try:
        wait_until(
            lambda: asked.count("arm1") >= 3 and asked.count("base1") >= 6,
            timeout=10,
            what="arm1 renewed again beside its lost renewal, base1 every round",
            seen=lambda: (asked.count("arm1"), asked.count("base1")),
        )
        # the later renewals of arm1 are answered: one (the lost one) stays in flight
        wait_until(lambda: r.in_flight("arm1") <= 1, timeout=5, what="arm1's answered renewals counted off")
    finally:
        hang.set()
        r.close()


def test_unanswered_renewals_are_said_once_until_one_is_answered(caplog):
    """Her lease runs out after a few unanswered renewals: the first is a warning naming the robot and why, the
    ones after it are not, and the first answered one after them says so."""
    from fabric.interfaces import ServiceError

    answers = iter([ServiceError("no reply in 2.0 s"), ServiceError("no reply in 2.0 s"), None, None])

    def ask(obj: str) -> OwnReply:
        exc = next(answers)
        if exc is not None:
            raise exc
        return _reply(obj)

    r = Renewal("alice", ask, dict, renew_s=1.0)
    r.hold("arm1")
    with caplog.at_level("WARNING", logger="robofabric.ownership"):
        for _ in range(4):
            r._renew_once("arm1")
    said = [m.getMessage() for m in caplog.records]
    assert len(said) == 2, said
    assert said[0].startswith("renewal of arm1 by alice: not renewed after") and "no reply in 2.0 s" in said[0]
    assert said[1] == "renewal of arm1 by alice: answered again (renewed)"


def test_a_round_that_began_late_is_said_with_how_late(caplog):
    """The owner's own process stood still (here its records took 1.2 s to read, once): the next round began over
    LATE_ROUND_S late, and it says so, so that a lease lost to her own stall is told apart from one lost on the way."""
    slow = [True]

    def records() -> dict[str, OwnershipRecord]:
        if slow[0]:
            slow[0] = False
            threading.Event().wait(LATE_ROUND_S + 0.3)  # as a paused process does, from the round's own thread
        return {}

    r = Renewal("alice", _reply, records, renew_s=0.05)
    r.hold("arm1")
    with caplog.at_level("WARNING", logger="robofabric.ownership"):
        r.start()
        try:
            wait_until(lambda: r.latest_late_s > 0, timeout=10, what="the late round said")
        finally:
            r.close()
    assert r.latest_late_s >= LATE_ROUND_S, r.latest_late_s
    assert any("renewals of alice: a round began" in m and "late" in m for m in caplog.messages), caplog.messages
