"""The pure core of whether a sim may take a step of a robot's move (sim_peer.shards.move_rule): who may move robots, what
a source may hand out and to whom, what a target may take in, and how long a source keeps what it handed out. Unit
tests, then property tests over random hosts."""

from __future__ import annotations

from hypothesis import given, settings, strategies as hs

from sim_peer.shards import move_rule as mr

SIMS = ["sim-a", "sim-b", "sim-c"]
ROBOTS = ["arm0", "base0", "base1"]


def test_only_a_serving_primary_that_rebuilds_and_has_no_standbys_moves_robots():
    assert mr.mover_refusal("sim-a", serving=True, can_rebuild=True, standbys=[]) == ""
    assert "is not serving" in mr.mover_refusal("sim-a", serving=False, can_rebuild=True, standbys=[])
    assert "cannot rebuild" in mr.mover_refusal("sim-a", serving=True, can_rebuild=False, standbys=[])
    assert mr.mover_refusal("sim-a", serving=True, can_rebuild=True, standbys=["sim-s1", "sim-s2"]) == (
        "sim sim-a has standbys (sim-s1, sim-s2): moving a robot of a replicated shard is not supported"
    )


def test_a_source_hands_out_a_robot_it_serves_not_its_last_to_another_live_sim():
    ok = dict(robots={"arm0", "base0"}, handed_out=set(), live={"sim-a", "sim-b"}, world="w")
    assert mr.move_out_refusal("base0", "sim-b", "sim-a", **ok) == ""
    assert mr.move_out_refusal("base9", "sim-b", "sim-a", **ok) == "sim sim-a does not serve robot base9"
    assert mr.move_out_refusal("base0", "sim-b", "sim-a", **{**ok, "handed_out": {"base0"}}) == (
        "robot base0 is being moved already"
    )
    assert "last robot" in mr.move_out_refusal("base0", "sim-b", "sim-a", **{**ok, "robots": {"base0"}})
    assert mr.move_out_refusal("base0", "sim-c", "sim-a", **ok) == (
        "sim sim-c is not another live sim of world 'w': base0 stays with sim sim-a"
    )
    assert "not another live sim" in mr.move_out_refusal("base0", "sim-a", "sim-a", **ok)


def test_a_source_hands_out_only_if_nothing_changed_while_its_target_was_asked():
    assert mr.unchanged("base0", term=3, asked_at_term=3, robots={"base0", "arm0"}, handed_out=set())
    assert not mr.unchanged("base0", term=4, asked_at_term=3, robots={"base0", "arm0"}, handed_out=set())
    assert not mr.unchanged("base0", term=3, asked_at_term=3, robots={"arm0"}, handed_out=set())
    assert not mr.unchanged("base0", term=3, asked_at_term=3, robots={"base0", "arm0"}, handed_out={"base0"})


def test_a_target_takes_in_a_robot_it_does_not_serve_at_a_term_not_below_its_own():
    assert mr.move_in_refusal("base0", "sim-b", term=5, my_term=5, robots={"arm1"}) == ""
    assert mr.move_in_refusal("base0", "sim-b", term=5, my_term=5, robots={"base0"}) == "sim sim-b already serves base0"
    assert mr.move_in_refusal("base0", "sim-b", term=4, my_term=5, robots=set()) == (
        "move term 4 is below sim sim-b's term 5: ask again"
    )


def test_what_a_source_kept_goes_once_its_target_serves_it_and_comes_back_when_nobody_fetched_it():
    assert mr.served_there("sim-b", 4, "sim-b", 4) and mr.served_there("sim-b", 4, "sim-b", 6)
    assert not mr.served_there("sim-b", 4, "sim-b", 3)  # the robot's joints from before the move
    assert not mr.served_there("sim-b", 4, "sim-c", 9)
    assert mr.unclaimed(closed=False, kept_move="m1", move_id="m1", fetched=False)
    assert not mr.unclaimed(closed=False, kept_move="m1", move_id="m1", fetched=True)
    assert not mr.unclaimed(closed=False, kept_move="m2", move_id="m1", fetched=False)  # a later move of it
    assert not mr.unclaimed(closed=False, kept_move=None, move_id="m1", fetched=False)  # served there already
    assert not mr.unclaimed(closed=True, kept_move="m1", move_id="m1", fetched=False)


@settings(max_examples=100, deadline=None)
@given(
    hs.sampled_from(ROBOTS),
    hs.sampled_from(SIMS),
    hs.sets(hs.sampled_from(ROBOTS)),
    hs.sets(hs.sampled_from(ROBOTS)),
    hs.sets(hs.sampled_from(SIMS)),
)
def test_property_a_robot_handed_out_leaves_a_sim_that_keeps_one_for_a_live_other(rid, to, robots, handed_out, live):
    """Whatever the host holds: a hand-out allowed moves a robot the source serves and is not moving yet, leaves it
    at least one, and goes to a live sim other than itself; one refused says so in words and names the robot or
    the sim."""
    why = mr.move_out_refusal(rid, to, "sim-a", robots=robots, handed_out=handed_out, live=live, world="w")
    if not why:
        assert rid in robots and rid not in handed_out and len(robots - {rid}) >= 1 and to in live and to != "sim-a"
    else:
        assert rid in why or to in why


@settings(max_examples=100, deadline=None)
@given(hs.sampled_from(ROBOTS), hs.integers(0, 9), hs.integers(0, 9), hs.sets(hs.sampled_from(ROBOTS)))
def test_property_a_robot_taken_in_is_new_to_the_target_and_never_at_an_older_term(rid, term, my_term, robots):
    why = mr.move_in_refusal(rid, "sim-b", term=term, my_term=my_term, robots=robots)
    assert (why == "") == (rid not in robots and term >= my_term)
