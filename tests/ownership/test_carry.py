"""ownership.carry: a snapshot's records overlaid with the records its authority published after it.

Contracts: a grant published after the snapshot is carried (its owner, its epoch) and its owner is known to the
restored users; a record of a lower epoch than the snapshot's, or of the same epoch published before it, is not;
whatever is heard, no object's epoch ends below the snapshot's; and the result restores to an authority state
whose owners are the carried ones.
"""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as stf

from fabric.interfaces import Header, OwnershipRecord
from ownership import snapshot, state as st
from ownership.carry import changed_hands, newer, overlay


def _rec(obj: str, owner: str = "", epoch: int = 0, seq: int = 0, queue: tuple[str, ...] = ()) -> OwnershipRecord:
    return OwnershipRecord(
        obj,
        owner=owner,
        epoch=epoch,
        queue=queue,
        lease_expiry=1.5 if owner else 0.0,
        header=Header(seq=seq, source="sim-a", term=3),
    )


def test_a_grant_after_the_snapshot_is_carried_with_its_epoch_and_its_owner():
    snap = (_rec("arm1", "", 515, seq=40), _rec("base1", "bob", 7, seq=12))
    users = {"next_rank": 1, "rank:bob": 0, "live:bob": True}
    records, new_users = overlay(snap, users, [_rec("arm1", "s01", 516, seq=41)], {"arm1": 41, "base1": 13})
    by = {r.object: r for r in records}
    assert (by["arm1"].owner, by["arm1"].epoch) == ("s01", 516)
    assert by["arm1"].lease_expiry == 0.0  # the restore gives her a whole lease
    assert by["base1"] == snap[1]
    assert new_users["rank:s01"] == 1 and new_users["live:s01"] is True and new_users["next_rank"] == 2
    restored = snapshot.restore(records, new_users, 100.0, lease_s=2.0, grace_s=10.0, authority="sim-b")
    assert restored.records["arm1"].owner == "s01" and restored.records["arm1"].epoch == 516
    assert "s01" in restored.live and restored.records["arm1"].lease_expiry >= 102.0


def test_older_records_and_those_the_snapshot_already_holds_are_not_carried():
    snap = (_rec("arm1", "s01", 516, seq=41),)
    assert not newer(_rec("arm1", "", 515, seq=99), snap[0], 42)  # a lower epoch, whatever its sequence number
    assert not newer(_rec("arm1", "s01", 516, seq=41), snap[0], 42)  # published before the snapshot
    assert newer(_rec("arm1", "s01", 516, seq=42, queue=("s02",)), snap[0], 42)  # a queue change after it
    records, _ = overlay(snap, {"next_rank": 0}, [_rec("arm1", "", 515, seq=99)], {"arm1": 42})
    assert records == snap


def test_an_away_user_is_not_made_live():
    snap = (_rec("arm1", "", 4, seq=3),)
    users = {"next_rank": 1, "rank:ann": 0, "away:ann": [5.0, "q:arm1"]}
    _, new_users = overlay(snap, users, [_rec("arm1", "bob", 5, seq=3, queue=("ann",))], {"arm1": 3})
    assert "live:ann" not in new_users and new_users["live:bob"] is True and new_users["rank:bob"] == 1


_objs = stf.sampled_from(["arm0", "arm1", "base0"])


@given(
    snap_epochs=stf.dictionaries(_objs, stf.integers(0, 50), min_size=1),
    heard=stf.lists(
        stf.tuples(_objs, stf.integers(0, 60), stf.integers(0, 20), stf.sampled_from(["", "a", "b"])), max_size=8
    ),
    seq=stf.integers(0, 20),
)
def test_no_epoch_ever_goes_below_the_snapshot_or_the_newest_heard(snap_epochs, heard, seq):
    snap = tuple(_rec(o, "", e, seq=seq) for o, e in sorted(snap_epochs.items()))
    heard_recs = [_rec(o, owner, e, seq=s) for o, e, s, owner in heard]
    newest: dict[str, OwnershipRecord] = {}
    for r in heard_recs:  # the follower keeps the newest (epoch, seq) of each object
        if r.object not in newest or (r.epoch, r.header.seq) >= (newest[r.object].epoch, newest[r.object].header.seq):
            newest[r.object] = r
    records, users = overlay(snap, {"next_rank": 0}, newest.values(), {o: seq for o in snap_epochs})
    by = {r.object: r for r in records}
    for o, e in snap_epochs.items():
        assert by[o].epoch >= e
    for o, r in newest.items():
        if o not in snap_epochs or r.epoch > snap_epochs[o]:
            assert by[o].epoch == r.epoch and by[o].owner == r.owner
    # the result is a state the authority restores from
    restored = snapshot.restore(records, users, 0.0, lease_s=2.0, grace_s=10.0, authority="x")
    assert {o: r.epoch for o, r in restored.records.items()} == {o: r.epoch for o, r in by.items()}
    assert all(r.owner in restored.live for r in restored.records.values() if r.owner)
    st.step(restored, st.Tick(0.1))  # and steps


def test_only_the_objects_whose_owner_or_epoch_moved_on_changed_hands():
    snap = (_rec("arm1", "alice", 2), _rec("base1", "bob", 5), _rec("arm2"))
    restored = (_rec("arm1", "", 3), _rec("base1", "bob", 5, queue=("carol",)), _rec("arm2"), _rec("base2", "dan", 1))
    assert changed_hands(snap, restored) == ("arm1", "base2")  # a queue change is no change of hands
