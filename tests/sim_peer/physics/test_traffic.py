"""Who gives way when bases wait for each other (issue 44): the pure decision, and the board the guards share."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings, strategies as st

from sim_peer.physics.traffic import GIVE_WAY_AFTER, Spot, Traffic, Waiter, crossing, cycle_of, gives_way, yields

IDS = ("base0", "base1", "base2", "base3", "base4")


def test_a_cycle_is_found_from_any_of_its_bases_and_nothing_else_is_one():
    pair = {"a": Waiter(1.0, "b"), "b": Waiter(1.5, "a")}
    assert cycle_of(pair, "a") == ("a", "b") and cycle_of(pair, "b") == ("b", "a")
    ring = {"a": Waiter(0.0, "b"), "b": Waiter(0.0, "c"), "c": Waiter(0.0, "a"), "d": Waiter(0.0, "a")}
    assert set(cycle_of(ring, "c")) == {"a", "b", "c"}
    assert cycle_of(ring, "d") == ()  # it waits for a cycle it is not part of
    assert cycle_of({"a": Waiter(0.0, "b")}, "a") == ()  # b does not wait: it moves or stands idle
    assert cycle_of({"a": Waiter(0.0, None)}, "a") == ()  # a wall, a box
    assert cycle_of({}, "a") == ()


def test_of_two_bases_waiting_for_each_other_the_later_waiter_gives_way_once_the_wait_is_long_enough():
    pair = {"base1": Waiter(1.0, "base2"), "base2": Waiter(1.5, "base1")}
    assert gives_way(pair, "base2", 1.5 + GIVE_WAY_AFTER - 0.01) is None  # not yet
    assert gives_way(pair, "base2", 1.5 + GIVE_WAY_AFTER) == "base1"
    assert gives_way(pair, "base1", 100.0) is None  # the earlier waiter keeps its way
    tie = {"base1": Waiter(1.0, "base2"), "base2": Waiter(1.0, "base1")}
    assert gives_way(tie, "base2", 9.0) == "base1" and gives_way(tie, "base1", 9.0) is None  # the greater id


boards = st.dictionaries(
    st.sampled_from(IDS), st.tuples(st.floats(0.0, 10.0), st.sampled_from((*IDS, None))), max_size=5
)


@settings(max_examples=300, deadline=None)
@given(board=boards, now=st.floats(0.0, 15.0))
def test_exactly_one_base_of_each_long_enough_cycle_gives_way_and_no_other_base_does(board, now):
    waiters = {r: Waiter(since, blocker) for r, (since, blocker) in board.items()}
    giving = {r: gives_way(waiters, r, now) for r in waiters}
    for r, to in giving.items():
        cycle = cycle_of(waiters, r)
        if to is not None:  # only a base of a cycle, to the base it waits for, after the wait
            assert cycle and to == waiters[r].blocker
            assert now - max(waiters[x].since for x in cycle) >= GIVE_WAY_AFTER
        if cycle:
            gave = [x for x in cycle if giving[x] is not None]
            long_enough = now - max(waiters[x].since for x in cycle) >= GIVE_WAY_AFTER
            assert len(gave) == (1 if long_enough else 0), (cycle, gave)
            if gave:  # the last to start waiting
                assert waiters[gave[0]].since == max(waiters[x].since for x in cycle)


def test_the_board_holds_spots_and_waiters():
    board = Traffic()
    board.stand("a", Spot(0.0, 0.0, 0.3))
    board.stand("b", Spot(1.0, 0.0, 0.3))
    assert board.others("a") == {"b": Spot(1.0, 0.0, 0.3)}
    board.wait("a", Waiter(1.0, "b"))
    board.wait("a", None)
    board.wait("b", None)  # not waiting: nothing to forget
    assert board.waiters == {}


def _way(a: tuple[float, float], b: tuple[float, float], n: int = 21) -> np.ndarray:
    return np.column_stack([np.linspace(a[0], b[0], n), np.linspace(a[1], b[1], n)])


def test_two_ways_that_cross_meet_where_either_first_comes_within_reach_of_the_other():
    mine, theirs = _way((-1.0, 0.0), (1.0, 0.0)), _way((0.0, -1.5), (0.0, 0.5))  # 0.1 m apart; they cross at 0, 0
    a, b = crossing(mine, theirs, 0.65)
    assert math.isclose(a, 0.3)  # x = -0.7 is clear, -0.6 within 0.65 of (0, 0)
    assert math.isclose(b, 0.8)  # y = -0.7 clear, -0.6 within 0.65 of (0, 0)
    assert crossing(theirs, mine, 0.65) == (b, a)
    assert crossing(mine, _way((-1.0, 1.0), (1.0, 1.0)), 0.65) is None  # side by side, 1 m apart
    assert crossing(mine, mine[:1], 0.65) is None  # a base that follows no path has no way


@settings(max_examples=200, deadline=None)
@given(
    pts=st.lists(st.tuples(st.floats(-3, 3), st.floats(-3, 3)), min_size=4, max_size=24),
    cut=st.integers(2, 20),
    reach=st.floats(0.1, 1.5),
)
def test_both_guards_weigh_the_same_two_numbers_and_exactly_one_base_yields(pts, cut, reach):
    a = np.array(pts[: max(2, min(cut, len(pts) - 2))])
    b = np.array(pts[len(a) :])
    ab, ba = crossing(a, b, reach), crossing(b, a, reach)
    assert (ab is None) == (ba is None)
    if ab is None:
        return
    assert ba == (ab[1], ab[0])  # symmetric: each guard computes the other's view
    assert yields("base1", ab[0], "base2", ab[1]) != yields("base2", ab[1], "base1", ab[0])  # one, not both or none
    # the one that goes first is the one nearer the meeting; up to it, the yielder's way is clear of the other's
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(a, axis=0).T))])
    clear = a[arc <= ab[0] + 1e-9][1:] if ab[0] > 0 else a[:0]
    d = np.hypot(clear[:, None, 0] - b[None, :, 0], clear[:, None, 1] - b[None, :, 1])
    assert (d >= reach).all()


@settings(max_examples=200, deadline=None)
@given(mine=st.floats(0.0, 3.0), theirs=st.floats(0.0, 3.0), held=st.sampled_from([None, "base1", "base2"]))
def test_a_base_that_yields_keeps_yielding_while_their_ways_meet_and_still_exactly_one_does(mine, theirs, held):
    board = {} if held is None else {held: "base2" if held == "base1" else "base1"}
    one = yields("base1", mine, "base2", theirs, board)
    two = yields("base2", theirs, "base1", mine, board)
    assert one != two
    if held is not None:
        assert one if held == "base1" else two  # the choice made stands, whatever the arcs say now
