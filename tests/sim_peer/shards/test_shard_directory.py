"""The shard directory built on its own: a real fabric, the live sims and the stop flag passed in, no ReplicaHost.

It learns the other sims' shards by asking ``srv/state`` (here another directory answers, as a sim's host does),
keeps only live sims' answers, counts only its shard's sims, and tells the election when a background learning
ends (``on_learnt``)."""

from __future__ import annotations

import threading

import numpy as np

from fabric import keys
from fabric.interfaces import Event, RobotState, WorldState
from robofabric.testing import wait_until
from sim_peer.shards.directory import SHARD_QUERY, ShardDirectory


def _directory(fab, mine, live, stopping=None, learnt=None):
    return ShardDirectory(
        fab,
        mine,
        live=lambda: frozenset(live),
        stopping=stopping or threading.Event(),
        on_learnt=(learnt.append if learnt is not None else lambda view: None),
    )


def _answering(fab, directory: ShardDirectory) -> None:
    """Serve ``srv/state`` shard queries from ``directory``, as a sim's host does."""
    fab.rpc.serve(keys.srv(fab.world, "state"), lambda key, request: directory.answer("standby"), expected=Event)


def test_a_directory_learns_the_live_sims_shards_and_counts_only_its_own(connect):
    a, b, c = connect("sim", "sim-a"), connect("sim", "sim-b"), connect("sim", "sim-c")
    live = {"sim-a", "sim-b", "sim-c"}
    mine = _directory(a, ["arm1"], live)
    _answering(b, _directory(b, ["arm1"], live))  # a standby of our shard
    _answering(c, _directory(c, ["base1"], live))  # another shard's sim
    # not asked yet, every sim counts as ours (one world, one shard)
    assert mine.view(frozenset(live)) == frozenset(live)
    assert mine.same_shard("sim-c")
    wait_until(
        lambda: (mine.learn(), len(mine.shards) == 2)[1], timeout=30, what="both sims' shards", seen=lambda: mine.shards
    )
    assert mine.shards == {"sim-b": frozenset({"arm1"}), "sim-c": frozenset({"base1"})}
    assert mine.view(frozenset(live)) == frozenset({"sim-a", "sim-b"})
    assert mine.same_shard("sim-b") and not mine.same_shard("sim-c")
    assert mine.standbys(live) == ["sim-b"]
    assert mine.standbys({"sim-a", "sim-c"}) == []  # sim-b's token gone: no standby of ours
    live.discard("sim-c")
    mine.learn()  # a sim no longer live is forgotten
    assert "sim-c" not in mine.shards


def test_learning_soon_tells_the_election_the_view_of_this_shard_once_done(connect):
    a, b = connect("sim", "sim-a"), connect("sim", "sim-b")
    live = {"sim-a", "sim-b"}
    learnt: list[frozenset[str]] = []
    mine = _directory(a, ["arm1"], live, learnt=learnt)
    _answering(b, _directory(b, ["base1"], live))
    # a first learning may miss sim-b's queryable on its way to the router: learn again until it is in
    wait_until(
        lambda: (mine.learn_soon(), learnt and learnt[-1] == frozenset({"sim-a"}))[1],
        timeout=30,
        what="the view without the other shard's sim",
        seen=lambda: learnt,
    )
    assert mine.shards == {"sim-b": frozenset({"base1"})}


def test_a_stopping_directory_learns_nothing_more(connect):
    a = connect("sim", "sim-a")
    stopping, learnt = threading.Event(), []
    mine = _directory(a, ["arm1"], {"sim-a"}, stopping, learnt)
    stopping.set()
    mine.learn_soon()
    assert not mine._learning and learnt == []  # no thread started: nothing will tell the election


def test_the_answer_and_about_mine_read_this_shards_robots(connect):
    a = connect("sim", "sim-a")
    mine = _directory(a, ["arm2", "arm1"], {"sim-a"})
    answer = mine.answer("primary")
    assert (answer.kind, answer.reason, answer.data, answer.header.source) == (
        SHARD_QUERY,
        "primary",
        {"robots": ["arm1", "arm2"]},
        "sim-a",
    )

    def state(*robots: str) -> WorldState:
        zero = np.zeros(1)
        return WorldState(0.0, 0, tuple(RobotState(r, "arm", zero, zero, zero) for r in robots), ())

    assert mine.about_mine(state("base1", "arm2"))
    assert not mine.about_mine(state("base1"))
    assert not mine.about_mine(answer)  # not a world state at all
    mine.mine = frozenset({"base1"})  # moved: replaced whole
    assert mine.about_mine(state("base1"))
