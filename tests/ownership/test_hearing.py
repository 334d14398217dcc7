"""The authority's hearing: a pause or a dead link makes it deaf; users it could not hear must show up again
within a lease and a second of the link being up, else they are due to leave. Times are values."""

from __future__ import annotations

from ownership.hearing import Hearing

LEASE = 2.0


def test_a_tick_after_more_than_half_a_lease_is_a_pause_and_deafens_for_a_lease_and_a_second():
    h = Hearing(LEASE, now=0.0)
    assert h.tick(0.0) == 0.0 and h.tick(0.5) == 0.0 and not h.deaf(0.6, connected=True)
    assert h.deaf(0.6, connected=False)  # the link down: deaf whatever the ticks say
    assert h.deaf(2.0, connected=True)  # no tick for 1.5 s: it may be its own trouble
    assert h.tick(2.0) == 1.5
    assert h.deaf(2.1, connected=True) and h.deaf(4.9, connected=True)  # resumed: deaf until 2.0 + 2 + 1
    h.tick(2.8), h.tick(3.6), h.tick(4.4), h.tick(5.0)
    assert not h.deaf(5.1, connected=True)


def test_a_suspected_user_is_due_only_a_lease_and_a_second_after_the_link_is_up():
    h = Hearing(LEASE, now=0.0)
    h.suspect("alice"), h.suspect("bob")
    assert h.pending
    assert h.due(10.0, connected=False) == []  # the link down: the clock does not run
    assert h.due(11.0, connected=True) == []  # the link up: the clock starts now
    h.confirm("bob")  # his token came back
    assert h.due(13.9, connected=True) == [] and h.pending
    assert h.due(14.1, connected=True) == ["alice"] and not h.pending
    assert h.due(20.0, connected=True) == []


def test_a_standbys_inherited_users_are_due_a_lease_and_a_second_after_it_starts():
    h = Hearing(LEASE, now=100.0, unconfirmed={"carol", "dave"})
    h.confirm("dave")
    assert h.due(102.9, connected=True) == []
    assert h.due(103.1, connected=True) == ["carol"]
