"""RoundRobin: every live compute peer in turn, refreshed as peers come and go (time passed in)."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from user_peer.spread import RoundRobin


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_turns_go_round_every_peer():
    rr = RoundRobin(lambda: ["c2", "c1", "c3"], clock=Clock())
    assert [rr.next() for _ in range(7)] == ["c1", "c2", "c3", "c1", "c2", "c3", "c1"]


def test_no_peer_known_means_the_nearest():
    assert RoundRobin(list, clock=Clock()).next() is None


def test_the_list_is_read_again_after_refresh_and_neither_repeats_nor_skips():
    clock, live = Clock(), ["c1", "c3"]
    rr = RoundRobin(lambda: list(live), refresh_s=2.0, clock=clock)
    assert rr.next() == "c1"
    live.append("c2")  # joins; not seen until the refresh
    assert rr.next() == "c3"
    clock.t = 2.5
    assert [rr.next() for _ in range(3)] == ["c1", "c2", "c3"]


def test_a_forgotten_peer_gets_no_turn_until_it_is_listed_again():
    clock = Clock()
    rr = RoundRobin(lambda: ["c1", "c2"], refresh_s=2.0, clock=clock)
    assert rr.next() == "c1"
    rr.forget("c2")
    assert [rr.next() for _ in range(2)] == ["c1", "c1"]
    clock.t = 3.0
    assert [rr.next() for _ in range(2)] == ["c2", "c1"]


@given(st.lists(st.sampled_from(["a", "b", "c", "d"]), min_size=1, max_size=4), st.integers(1, 40))
def test_fair_share(peers, n):
    rr = RoundRobin(lambda: peers, clock=Clock())
    handed = [rr.next() for _ in range(n)]
    counts = [handed.count(p) for p in set(peers)]
    assert max(counts) - min(counts) <= 1
