"""Who gives way when bases wait for each other (issue 44): the pure decision, and the board the guards share."""

from __future__ import annotations

from hypothesis import given, settings, strategies as st

from sim_peer.traffic import GIVE_WAY_AFTER, Spot, Traffic, Waiter, cycle_of, gives_way

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


boards = st.dictionaries(st.sampled_from(IDS), st.tuples(st.floats(0.0, 10.0), st.sampled_from((*IDS, None))), max_size=5)


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
