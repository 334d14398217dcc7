"""A sim's role is published (sim_peer.replica.role_token): the token ``peer/sim/{id}/{role}/{term}/{leader}``, which tests and
the soak read through :class:`robofabric.testing.SimRoles` instead of the sim's log lines."""

from __future__ import annotations

import pytest

from fabric import keys
from fabric.gate import OpenGate
from robofabric.testing import SimRole, SimRoles, client
from sim_peer.replica import election as el
from sim_peer.replica.replica_host import ReplicaHost
from sim_peer.replica.role_token import shown
from sim_peer.physics.world import SimWorld


def test_a_role_key_names_the_sim_its_role_term_and_leader_and_parses_back():
    key = keys.sim_role("w", "sim-b", "standby", 3, "sim-a")
    assert key == "rf/w/peer/sim/sim-b/standby/3/sim-a"
    p = keys.parse(key)
    assert (p.category, p.subject, p.leaf, p.rest) == ("sim_role", "sim-b", "standby", ("3", "sim-a"))
    assert (
        keys.sim_roles_all("w") == "rf/w/peer/sim/*/*/*/*"
        and keys.parse(keys.peer("w", "sim", "sim-b")).category == "peer"
    )
    for bad in (
        ("sim-b", "leader", 3, "sim-a"),
        ("sim-b", "primary", -1, "sim-b"),
        ("sim b", "primary", 1, "sim-b"),
        ("sim-b", "primary", 1, ""),
    ):
        with pytest.raises(ValueError):
            keys.sim_role("w", *bad)
    with pytest.raises(ValueError):
        keys.parse("rf/w/peer/sim/sim-b/leader/3/sim-a")  # no such role: not a role token


def test_what_a_sim_shows_follows_its_election_and_whether_it_serves():
    assert shown(el.start("a", standby=False), serving=True) == ("primary", 1, "a")
    assert shown(el.start("a", standby=False), serving=False) is None  # a take-over still restoring the world
    assert shown(el.start("b", standby=True), serving=False) is None  # following nobody yet
    follows = el.step(el.start("b", standby=True), el.Heard("a", 1))[0]
    assert shown(follows, serving=False) == ("standby", 1, "a")
    assert (
        shown(follows, serving=False, holds=False) is None
    )  # no state held yet: a take-over would start from the scene
    took = el.step(follows, el.Peers(frozenset({"b"})))[0]
    assert shown(took, serving=True) == ("primary", 2, "b")
    stepped = el.step(el.start("a", standby=False), el.Heard("b", 2))[0]
    assert shown(stepped, serving=True) == ("standby", 2, "b")  # muzzled and leaving: no longer the primary


def test_the_watch_keeps_what_each_sim_shows_now_and_every_role_shown():
    class Fab:  # the watch's one call into a session: where the tokens come from (its callback, called by hand)
        world = "w"

        def watch_tokens(self, expr, callback):
            assert expr == keys.sim_roles_all("w")
            self.callback = callback

    fab = Fab()
    roles = SimRoles(fab)  # type: ignore[arg-type]
    on = fab.callback
    on(keys.sim_role("w", "sim-b", "standby", 1, "sim-a"), True)
    on("rf/w/peer/sim/sim-b/chief/1/x", True)  # made up: nobody's role
    assert roles.now("sim-b") == SimRole("sim-b", "standby", 1, "sim-a") and roles.role("sim-a") == ""
    on(keys.sim_role("w", "sim-b", "primary", 2, "sim-b"), True)  # declared before the old one goes
    on(keys.sim_role("w", "sim-b", "standby", 1, "sim-a"), False)
    assert (
        roles.role("sim-b") == "primary" and roles.ever("sim-b", "standby", 1) and not roles.ever("sim-b", "standby", 2)
    )
    assert roles.wait("sim-b", "primary", term=2, timeout=1) == SimRole("sim-b", "primary", 2, "sim-b")
    on(keys.sim_role("w", "sim-b", "primary", 2, "sim-b"), False)  # killed: its tokens go
    assert roles.now("sim-b") is None and len(roles.shown) == 2


def _gate(fabric, world, restored):
    return OpenGate()


@pytest.mark.slow  # two sim hosts and a router: seconds
def test_a_primary_and_its_standby_show_their_roles_and_a_take_over_shows_the_new_term(world, router, connect):
    roles = SimRoles(connect("tool", "watcher"))
    hosts = []
    try:
        for sim, standby in (("sim-a", False), ("sim-b", True)):
            fab = client(world, router[1], kind="sim", peer_id=sim)
            hosts.append(ReplicaHost(fab, SimWorld("combined", seed=1), _gate, standby=standby).open())
        primary, standby = hosts
        assert roles.wait("sim-a", "primary", term=1, timeout=20) == SimRole("sim-a", "primary", 1, "sim-a")
        roles.wait("sim-b", "standby", term=1, leader="sim-a", timeout=20, seen=lambda: standby.election)
        # shown once it holds sim-a's state: killed now, it carries the world on
        assert standby.follower.holds_state() and standby.follower.snapshot.header.source == "sim-a"
        primary.close()
        primary.fabric.close()  # its tokens go: the standby takes over
        roles.wait("sim-b", "primary", term=2, leader="sim-b", timeout=30, seen=lambda: standby.election)
        assert standby.takeovers and standby.takeovers[0]["from"] == "sim-a" and roles.now("sim-a") is None
        assert not roles.ever("sim-a", "standby") and not roles.ever("sim-b", "primary", 1)
    finally:
        for host in hosts:
            host.close()
            host.fabric.close()
