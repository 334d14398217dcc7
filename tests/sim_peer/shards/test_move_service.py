"""The moves built on their own: two sims' move services on real fabrics and real worlds, each with a small server
in the host's place (:class:`~sim_peer.shards.moving.Rebuilder`), the election's state and a fake clock passed
in, no ReplicaHost.

A robot handed from one sim to the other leaves the source's world and joins the target's, both under the move's
term; a standby refuses, counts and only logs; the source forgets what it kept once the target serves it."""

from __future__ import annotations

import threading
from dataclasses import replace

import numpy as np
import pytest

from fabric import keys
from fabric.interfaces import Event, ServiceError, WorldState
from robofabric.testing import wait_until
from sim_peer.physics import capture
from sim_peer.physics.world import SimWorld
from sim_peer.replica import election as el
from sim_peer.shards import handoff as ho
from sim_peer.shards.moving import MoveService


class WorldServer:
    """The host's side of the seam: a real world, rebuilt and restored as the host does, under the move's term."""

    def __init__(self, fab, robots: list[str], *, role: str = el.PRIMARY, can_rebuild: bool = True) -> None:
        self.world = SimWorld("warehouse", robots, scene_robots=False, seed=1)

        def build(placements: list) -> SimWorld:
            return SimWorld("warehouse", placements, scene_robots=False, seed=1)

        self.rebuild = build if can_rebuild else None
        self.closed, self.serving = False, True
        self.election = el.Election(fab.peer_id, role, 1 if role == el.PRIMARY else 0, fab.peer_id)
        self.lock, self.said, self.now = threading.RLock(), [], 5.0
        self.standbys: list[str] = []
        self.moves = MoveService(
            fab,
            self,
            serving_lock=self.lock,
            election=lambda: self.election,
            live=lambda: frozenset({"sim-a", "sim-b"}),
            standbys=lambda live: list(self.standbys),
            announce=self.said.append,
            clock=lambda: self.now,
        )
        fab.rpc.serve(keys.srv_move_served(fab.world, fab.peer_id), self.moves.on_query, expected=Event)

    def stop_serving(self) -> tuple[WorldState, dict]:
        t, steps, robots, objects = capture.capture(self.world)
        self.serving = False
        return WorldState(t, steps, robots, ()), dict(self.world.placements)

    def serve_rebuilt(self, world: SimWorld, state: WorldState, term: int, seqs: dict[str, int]) -> None:
        capture.restore(world, state)
        self.world, self.serving = world, True
        self.election = replace(self.election, term=term)

    def serve_again(self, placements, state: WorldState, term: int) -> None:
        self.serve_rebuilt(self.rebuild(list(placements.values())), state, term, {})


def _ask(fab, sim: str, request: Event) -> Event:
    return ho.ask(fab, sim, "tool", request, 10.0)


def _first_answer(fab, sim: str, request: Event) -> Event | ho.MoveError:
    """The first answer (or refusal) of ``sim`` to ``request``, asked until its queryable reached the router."""

    def answer() -> Event | ho.MoveError | None:
        try:
            return ho.ask(fab, sim, "tool", request, 2.0)
        except ho.NoAnswer:
            return None  # not declared at the router yet
        except ho.MoveError as exc:
            return exc

    return wait_until(answer, timeout=30, what=f"sim {sim}'s move service")


def test_a_robot_moves_between_two_sims_through_their_move_services(connect):
    a, b, tool = connect("sim", "sim-a"), connect("sim", "sim-b"), connect("tool", "tool")
    src = WorldServer(a, ["reeman:base0@0,0", "reeman:base2@0,1"])
    dst = WorldServer(b, ["reeman:base1@1.5,0,180"])
    term = ho.move_term(src.election.term, dst.election.term)
    check = _first_answer(tool, "sim-a", ho.step(ho.MOVE_CHECK, "base2", to="sim-b", asker="tool"))
    assert check.data["term"] == 1
    assert _first_answer(tool, "sim-b", ho.step(ho.MOVE_CHECK, "base2", to="sim-b", asker="tool")).data["term"] == 1
    out = _ask(tool, "sim-a", ho.step(ho.MOVE_OUT, "base2", to="sim-b", term=term, asker="tool"))
    assert set(src.world.robots) == {"base0"} and src.election.term == term
    assert set(src.moves.handed_out) == {"base2"} and src.moves.handed_out["base2"].at == 5.0  # on its clock
    _ask(
        tool,
        "sim-b",
        ho.step(ho.MOVE_IN, "base2", to="sim-b", source="sim-a", term=term, move_id=out.data["move"], asker="tool"),
    )
    assert set(dst.world.robots) == {"base1", "base2"} and dst.election.term == term
    assert np.isclose(dst.world.robots["base2"].ctrl.y, 1.0)  # where the source had it
    assert any("took base2 in from sim-a" in s for s in dst.said) and any("handed base2 out" in s for s in src.said)
    src.moves.seen_serving("base2", "sim-b", term - 1)  # an older term: not the target serving it after the move
    assert "base2" in src.moves.handed_out
    src.moves.seen_serving("base2", "sim-b", term)
    assert src.moves.handed_out == {}


def test_a_sim_that_may_not_move_refuses_and_counts(connect):
    a, tool = connect("sim", "sim-a"), connect("tool", "tool")
    standby = WorldServer(a, ["reeman:base0@0,0"], role=el.STANDBY)
    refused = _first_answer(tool, "sim-a", ho.step(ho.MOVE_CHECK, "base0", to="sim-b", asker="tool"))
    assert isinstance(refused, ho.MoveError) and "not serving" in str(refused)
    assert a.counters["moves_refused"] == 1
    standby.election, standby.standbys = replace(standby.election, role=el.PRIMARY), ["sim-c"]
    with pytest.raises(ho.MoveError, match="has standbys \\(sim-c\\)"):
        _ask(tool, "sim-a", ho.step(ho.MOVE_CHECK, "base0", to="sim-b", asker="tool"))
    standby.standbys, standby.rebuild = [], None
    with pytest.raises(ho.MoveError, match="cannot rebuild"):
        _ask(tool, "sim-a", ho.step(ho.MOVE_CHECK, "base0", to="sim-b", asker="tool"))
    with pytest.raises(ServiceError, match="a move's step is an Event"):
        standby.moves.on_query(keys.srv_move(a.world, "sim-a", "tool"), "not an event")
    assert a.counters["moves_refused"] == 4  # each refusal counted once
