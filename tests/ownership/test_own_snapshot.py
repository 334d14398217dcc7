"""Ownership state carried from one authority to another (ownership.snapshot): property tests.

After any history, export on the old authority's clock and restore on another clock: every record
(owner, epoch, queue, motion state), the join order, who is live, away (with the grace left) and
unproven are the same, leases resume with what remained but never less than one lease, and the
restored state goes on behaving exactly like the original under the same later events."""

from __future__ import annotations

from dataclasses import replace

from hypothesis import example, given, settings, strategies as hs

from fabric.codec import decode, encode
from fabric.interfaces import WorldState
from ownership import snapshot
from ownership import state as st

from tests.ownership.test_state import GRACE, LEASE, OBJECTS, build, check_invariants, events


def _run(s, seq, now):
    for raw in seq:
        now += raw[-1] if raw[0] != "motion" and isinstance(raw[-1], float) else 0.0
        s, _ = st.step(s, build(raw, now))
    return s, now


@settings(max_examples=200, deadline=None)
@given(events(), events(), hs.floats(-1e6, 1e6))
# the authority's last tick travels too: without it the restored one read a tick 3 s later as no pause of its
# own and expired a's lease, where the old one would have given her a whole lease to renew
@example(
    history=[("tick", 0.0), ("request", "a", "arm", False, 0.0)],
    later=[("join", "a", 0.0), ("join", "a", 1.0), ("join", "a", 1.0), ("tick", 1.0)],
    offset=0.0,
)
def test_restore_of_export_is_the_same_state_on_another_clock(history, later, offset):
    s, now = _run(st.initial(OBJECTS, lease_s=LEASE, grace_s=GRACE, authority="sim-a"), history, 0.0)
    recs, users = snapshot.export(s, now)
    travelled = decode(encode(WorldState(time=0.0, steps=0, robots=(), objects=(), records=recs, users=users)))
    recs, users = travelled.records, travelled.users  # as it travels in WorldState
    r = snapshot.restore(recs, users, now + offset, lease_s=LEASE, grace_s=GRACE, authority="sim-b")
    check_invariants(r)
    assert set(r.records) == set(s.records)
    for obj, a in s.records.items():
        b = r.records[obj]
        assert (b.owner, b.epoch, b.queue, b.state, b.policy, b.authority) == (
            a.owner,
            a.epoch,
            a.queue,
            a.state,
            a.policy,
            "sim-b",
        )
        if a.owner:
            assert b.lease_expiry - (now + offset) >= LEASE - 1e-6
            assert abs(b.lease_expiry - (now + offset) - max(a.lease_expiry - now, LEASE)) < 1e-6
    assert dict(r.rank) == dict(s.rank) and r.live == s.live and r.next_rank == s.next_rank
    assert {u: abs((a.deadline - now) - (r.away[u].deadline - now - offset)) < 1e-6 for u, a in s.away.items()} == {
        u: True for u in s.away
    }
    assert {u: (a.owned, a.queued) for u, a in s.away.items()} == {u: (a.owned, a.queued) for u, a in r.away.items()}
    assert set(r.unproven) == set(s.unproven)
    # the same later events give the same owners and epochs (leases of the original topped up the same way)
    s2 = replace(
        s,
        records={
            o: replace(rec, lease_expiry=now + max(rec.lease_expiry - now, LEASE)) if rec.owner else rec
            for o, rec in s.records.items()
        },
    )
    a_end, _ = _run(s2, later, now)
    b_end, _ = _run(r, later, now + offset)
    # times in `later` are relative: shift the restored run by the offset
    assert {o: (x.owner, x.epoch, x.queue) for o, x in a_end.records.items()} == {
        o: (x.owner, x.epoch, x.queue) for o, x in b_end.records.items()
    }
