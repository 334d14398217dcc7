"""The pure parts of moving a robot between sims (sim_peer/shards/handoff.py): the term, the records and users merged,
the handoff as it travels in an event."""

from __future__ import annotations

import numpy as np
import pytest

from fabric.codec import decode, encode
from fabric.interfaces import Event, OwnershipRecord, RobotState
from robots.description import SceneRobot
from sim_peer.shards import handoff as ho


def _rec(obj: str, owner: str = "", epoch: int = 0, queue: tuple[str, ...] = ()) -> OwnershipRecord:
    return OwnershipRecord(obj, "exclusive", owner, epoch, 1.5 if owner else 0.0, queue, authority="sim-a")


def test_the_move_term_is_above_both_sims():
    assert ho.move_term(1, 1) == 2
    assert ho.move_term(3, 1) == 4 and ho.move_term(1, 5) == 6


def test_records_lose_the_moved_robot_at_the_source_and_gain_it_at_the_target():
    recs = (_rec("base0", "bob", 2), _rec("base2", "alice", 7))
    assert [r.object for r in ho.merge_records(recs, drop="base2")] == ["base0"]
    moved = _rec("base2", "alice", 7)
    assert ho.merge_records((_rec("base1"),), add=moved) == (_rec("base1"), moved)
    assert ho.merge_records((_rec("base2", "carol", 1),), add=moved) == (moved,)  # the handed-out record wins


def test_the_users_a_record_names_move_with_it_ranked_after_the_targets_own():
    source = {
        "next_rank": 3,
        "rank:zed": 0,
        "rank:alice": 1,
        "rank:bob": 2,
        "live:alice": True,
        "away:bob": [4.0, "q:base2"],
        "live:zed": True,
    }
    named = ho.named_users(source, _rec("base2", "alice", 7, queue=("bob",)))
    assert named == {"rank:alice": 1, "rank:bob": 2, "live:alice": True, "away:bob": [4.0, "q:base2"]}
    target = {"next_rank": 2, "rank:carol": 0, "rank:bob": 1, "live:carol": True, "live:bob": True}
    merged = ho.merge_users(target, named)
    assert merged["rank:carol"] == 0 and merged["rank:bob"] == 1  # the target's join order stands
    assert merged["rank:alice"] == 2 and merged["next_rank"] == 3 and merged["live:alice"] is True
    assert "away:bob" not in merged  # live at the target: not away
    assert ho.named_users(source, None) == {}


def test_a_handoff_travels_in_an_event_and_back():
    state = RobotState(
        "base2",
        "mobile",
        np.array([1.0, 2.0, 0.5]),
        np.array([0.3, 0.0]),
        np.array([0.3, 0.0]),
        np.zeros((0, 2)),
        {"wheel_l": 1.25},
    )
    h = ho.Handoff(
        state,
        SceneRobot("reeman", "base2", (0.0, 2.0, 0.0, 0.0)),
        _rec("base2", "alice", 7),
        {"rank:alice": 1, "live:alice": True},
        {"rf/w/robot/base2/pose": 41},
        2,
        "sim-a",
    )
    ev = decode(encode(ho.to_event(ho.MOVE_OUT, "base2", "sim-b", h, term=2, source="sim-a")), Event)
    back = ho.from_event(ev)
    assert back.placement == h.placement and back.record == h.record and back.term == 2 and back.source == "sim-a"
    assert dict(back.users) == dict(h.users) and dict(back.seqs) == dict(h.seqs)
    assert np.array_equal(back.state.q, state.q) and back.state.extra == state.extra
    assert ev.data["to"] == "sim-b" and ev.data["term"] == 2


def test_an_event_without_a_handoff_or_about_another_robot_is_refused():
    with pytest.raises(ho.MoveError, match="no robot handed out"):
        ho.from_event(ho.to_event(ho.MOVE_IN, "base2", "sim-b", term=2))
    state = RobotState("base2", "mobile", np.zeros(3), np.zeros(2), np.zeros(2))
    h = ho.Handoff(state, SceneRobot("reeman", "base2"), None)
    ev = ho.to_event(ho.MOVE_IN, "base9", "sim-b", h, term=2)
    with pytest.raises(ho.MoveError, match="disagree"):
        ho.from_event(ev)


def _kept(to: str = "sim-b", move: str = "m1", term: int = 2, fetched: bool = False) -> ho.HandedOut:
    state = RobotState("base2", "mobile", np.zeros(3), np.zeros(2), np.zeros(2))
    h = ho.Handoff(state, SceneRobot("reeman", "base2"), _rec("base2", "alice", 7), term=term, source="sim-a")
    return ho.HandedOut(h, to, move, placement=SceneRobot("reeman", "base2"), fetched=fetched)


def test_a_source_gives_a_robot_only_to_the_sim_of_the_move_that_handed_it_out():
    """Steal, clone, phantom: a target gets a robot only from what its source kept for it."""
    assert ho.fetch_refusal(_kept(), "base2", "sim-b", 2, "m1") == ""
    assert "no robot base2 was handed out" in ho.fetch_refusal(None, "base2", "sim-b", 2, "m1")
    assert "to sim sim-b, not to sim sim-c" in ho.fetch_refusal(_kept(), "base2", "sim-c", 2, "m1")
    assert "another move" in ho.fetch_refusal(_kept(), "base2", "sim-b", 2, "forged")
    assert "at term 2, not 100" in ho.fetch_refusal(_kept(), "base2", "sim-b", 100, "m1")


def test_a_source_takes_back_only_what_no_live_target_took():
    """Two sims never serve one robot: a handoff the target fetched comes back only once it gave it back or is gone."""
    assert ho.take_back_refusal(_kept(), "base2", "m1", target_live=True) == ""
    assert ho.take_back_refusal(_kept(), "base2", None, target_live=True) == ""  # the source's own timer
    assert "took robot base2" in ho.take_back_refusal(_kept(fetched=True), "base2", "m1", target_live=True)
    assert ho.take_back_refusal(_kept(fetched=True), "base2", "m1", target_live=False) == ""
    assert "another move" in ho.take_back_refusal(_kept(), "base2", "other", target_live=True)
    assert "no robot base2" in ho.take_back_refusal(None, "base2", "m1", target_live=True)


def test_a_target_checks_the_robot_the_source_and_the_term_of_what_it_fetched():
    h = _kept().handoff
    ho.check_handoff(h, "base2", "sim-a", 2)
    with pytest.raises(ho.MoveError, match="another robot"):
        ho.check_handoff(h, "base0", "sim-a", 2)
    with pytest.raises(ho.MoveError, match="not from sim sim-c"):
        ho.check_handoff(h, "base2", "sim-c", 2)
    with pytest.raises(ho.MoveError, match="not at the move's term 100"):
        ho.check_handoff(h, "base2", "sim-a", 100)


def test_a_step_carries_no_robot_only_names_and_the_term():
    ev = decode(
        encode(ho.step(ho.MOVE_IN, "base2", to="sim-b", source="sim-a", term=3, move_id="m1", asker="t")), Event
    )
    assert ev.kind == "move_in" and ev.object == "base2"
    assert ev.data == {"to": "sim-b", "from": "sim-a", "term": 3, "move": "m1"}
    assert set(ho.STEPS) == {"move_check", "move_out", "move_prepare", "move_fetch", "move_in"}
