"""Several sims, one world (docs/sim.md): two sims of disjoint robots serve one world as shards.

A user sees both robots without knowing which sim runs which, owns and drives both; killing one sim
leaves the other's robot live (poses keep coming) and owned (same owner, same epoch), and the user is
told which robots went. A duplicate robot id and another scene are still refused with one line
(test_world_conflict.py)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time

import pytest

from fabric import keys
from fabric.interfaces import WorldInfo
from robofabric.testing import SimRoles, client_config, robofabric_cmd, wait_until
from user_peer.api import Base, World

pytestmark = pytest.mark.slow

BASE0 = ("--scene", "warehouse", "--no-scene-robots", "--robot", "reeman:base0@0,0")
BASE1 = ("--scene", "warehouse", "--no-scene-robots", "--robot", "reeman:base1@1.5,0,180")


def _parts(fab, world: str) -> dict[str, WorldInfo]:
    from fabric.interfaces import ServiceError

    try:
        return {
            r.source: r.message
            for r in fab.rpc.query(keys.srv(world, "world"), timeout=2.0, expected=WorldInfo, all_replies=True)
        }
    except ServiceError:
        return {}


def _two_shards(world, router, connect, procs, a=BASE0, b=BASE1):
    """sim-a (``a``: base0), then sim-b (``b``: base1) joining as a shard, both serving; (common CLI args, probe,
    sim-a, sim-b)."""
    common = ("--world", world, "--connect", f"tcp/127.0.0.1:{router[1]}")
    probe = connect("tool", "probe")
    sim_a = procs.start(robofabric_cmd("sim", *a, *common, "--id", "sim-a"), name="sim-a")
    wait_until(
        lambda: "sim-a" in _parts(probe, world),
        timeout=60,
        what="sim-a serving",
        seen=lambda: procs.output(sim_a)[-800:],
    )
    sim_b = procs.start(robofabric_cmd("sim", *b, *common, "--id", "sim-b"), name="sim-b")
    wait_until(
        lambda: set(_parts(probe, world)) == {"sim-a", "sim-b"},
        timeout=60,
        what="both sims serving",
        seen=lambda: procs.output(sim_b)[-800:],
    )
    return common, probe, sim_a, sim_b


def test_two_sims_serve_one_world_and_one_sims_loss_takes_its_robots_only(world, router, connect, procs):
    common, probe, sim_a, sim_b = _two_shards(world, router, connect, procs)
    roles = SimRoles(probe)  # the roles the sims show (their role tokens)
    assert "as a shard beside sim-a (base0)" in procs.output(sim_b)
    parts = _parts(probe, world)
    assert [r.id for r in parts["sim-a"].robots] == ["base0"] and [r.id for r in parts["sim-b"].robots] == ["base1"]
    assert parts["sim-a"].objects and not parts["sim-b"].objects  # the first sim keeps the scene objects

    # `robofabric call srv/world` prints the one world: both robots, each with its sim
    r = subprocess.run(
        robofabric_cmd("call", "srv/world", "--json", *common), capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 0, r.stderr[-800:]
    (only,) = [json.loads(ln) for ln in r.stdout.splitlines() if ln.strip()]
    assert {(x["id"], x["sim"]) for x in only["message"]["robots"]} == {("base0", "sim-a"), ("base1", "sim-b")}
    # `robofabric own list`: every record at its own sim; the scene objects' at the first sim
    r = subprocess.run(robofabric_cmd("own", "list", "--json", *common), capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-800:]
    auth = {rec["object"]: rec["authority"] for rec in json.loads(r.stdout)["records"]}  # one JSON document
    assert auth["base0"] == "sim-a" and auth["base1"] == "sim-b", auth
    assert {a for o, a in auth.items() if o not in ("base0", "base1")} == {"sim-a"}, auth

    w = World(client_config(world, router[1]), "alice", timeout=10.0)
    try:
        assert w.robots() == ["base0", "base1"]
        b0, b1 = w.robot("base0"), w.robot("base1")
        assert isinstance(b0, Base) and isinstance(b1, Base)
        for b in (b0, b1):
            b.wait_for("pose", timeout=20)
            b.request(timeout=10)
        rec0, rec1 = w.ownership.record("base0"), w.ownership.record("base1")
        assert (rec0.owner, rec0.authority) == ("alice", "sim-a") and (rec1.owner, rec1.authority) == ("alice", "sim-b")
        x0, x1 = b0.xy_theta[0], b1.xy_theta[0]
        b0.twist(0.3, 0.0)
        b1.twist(0.3, 0.0)  # base1 faces -x: it drives away from base0
        wait_until(
            lambda: b0.xy_theta[0] > x0 + 0.1 and b1.xy_theta[0] < x1 - 0.1,
            timeout=20,
            what="both bases driving",
            seen=lambda: (b0.xy_theta, b1.xy_theta, w.events[-3:]),
        )
        b0.stop(timeout=10)
        b1.stop(timeout=10)
        gone: list[tuple[str, list[str]]] = []
        w.on_robots_gone(lambda sim, robots: gone.append((sim, robots)))
        epoch0 = w.ownership.record("base0").epoch

        procs.kill(sim_b)  # SIGKILL, by pid
        wait_until(lambda: gone, timeout=20, what="alice told which robots went", seen=lambda: w.sims())
        assert gone == [("sim-b", ["base1"])] and w.robots_gone == ["base1"]
        assert w.world_alive and w.sims() == ["sim-a"]
        assert w.robots() == ["base0"]  # the world is what the live sims serve
        # base0 lives on: poses keep coming, alice still owns it with the same epoch, and drives it
        t = time.time_ns()
        wait_until(
            lambda: b0.pose is not None and b0.pose.header.wall_ns > t,
            timeout=10,
            what="base0's poses after sim-b died",
        )
        x = b0.xy_theta[0]
        b0.twist(0.3, 0.0)
        wait_until(lambda: b0.xy_theta[0] > x + 0.1, timeout=20, what="base0 driving after sim-b died")
        b0.stop(timeout=10)
        rec = w.ownership.record("base0")
        assert (rec.owner, rec.epoch, rec.authority) == ("alice", epoch0, "sim-a")
        assert sim_a.poll() is None and not roles.ever("sim-a", "standby")  # it never stepped down
    finally:
        w.close()


def test_a_shards_standby_takes_its_robots_over_and_the_other_shard_is_not_fenced(world, router, connect, procs):
    """sim-b's standby (sim-b2) takes base1 over with term 2 when sim-b dies, although sim-a, of another shard,
    has the lowest id of the live sims; base0 goes on at term 1, believed beside base1's term 2; alice keeps
    both robots with their epochs."""
    common, probe, sim_a, sim_b = _two_shards(world, router, connect, procs)
    roles = SimRoles(probe)  # the roles the sims show (their role tokens)
    sim_b2 = procs.start(robofabric_cmd("sim", *BASE1, *common, "--id", "sim-b2", "--standby"), name="sim-b2")
    roles.wait("sim-b2", "standby", term=1, leader="sim-b", timeout=60, seen=lambda: procs.output(sim_b2)[-800:])
    w = World(client_config(world, router[1]), "alice", timeout=10.0)
    try:
        b0, b1 = w.robot("base0"), w.robot("base1")
        for b in (b0, b1):
            b.wait_for("pose", timeout=20)
            b.request(timeout=10)
        epochs = {r: w.ownership.record(r).epoch for r in ("base0", "base1")}
        gone: list[tuple[str, list[str]]] = []
        w.on_robots_gone(lambda sim, robots: gone.append((sim, robots)))
        # drive base1 a little first: the standby carries ownership over from its last snapshot (polled every
        # 50 ms), and a grant in the last poll period before the death is not in it (docs/sim.md, limits)
        x = b1.xy_theta[0]
        b1.twist(0.3, 0.0)
        wait_until(lambda: b1.xy_theta[0] < x - 0.1, timeout=20, what="base1 driving under sim-b")
        b1.stop(timeout=10)

        procs.kill(sim_b)
        roles.wait(
            "sim-b2", "primary", term=2, timeout=30, seen=lambda: procs.output(sim_b2)[-800:]
        )  # base1 taken over
        assert "from the state of sim-b" in procs.output(sim_b2)
        assert gone == [("sim-b", ["base1"])]
        wait_until(
            lambda: b1.pose is not None and b1.pose.header.source == "sim-b2" and b1.pose.header.term == 2,
            timeout=20,
            what="base1's poses from sim-b2 at term 2",
        )
        t = time.time_ns()
        wait_until(
            lambda: b0.pose is not None and b0.pose.header.wall_ns > t,
            timeout=10,
            what="base0's term-1 poses still believed",
        )
        assert b0.pose.header.term == 1 and b0.pose.header.source == "sim-a"
        wait_until(lambda: sorted(w.robots()) == ["base0", "base1"], timeout=20, what="base1 in the world again")
        assert {(r.id, r.sim) for r in w.info().robots} == {("base0", "sim-a"), ("base1", "sim-b2")}
        # alice keeps both, same epochs, and base1's new authority takes her commands
        wait_until(
            lambda: (w.ownership.record("base1") or b1.record).authority == "sim-b2",
            timeout=20,
            what="base1's record from sim-b2",
        )
        for r in ("base0", "base1"):
            rec = w.ownership.record(r)
            assert (rec.owner, rec.epoch) == ("alice", epochs[r]), rec
        x = b1.xy_theta[0]
        b1.twist(0.3, 0.0)
        wait_until(lambda: b1.xy_theta[0] < x - 0.1, timeout=20, what="base1 driving under sim-b2")
        b1.stop(timeout=10)
        assert sim_a.poll() is None and {(r.role, r.term) for r in roles.shown if r.sim == "sim-a"} == {("primary", 1)}
    finally:
        w.close()


def test_a_paused_shard_stalls_its_robots_only_and_comes_back_with_its_owners(world, router, connect, procs):
    """SIGSTOP on sim-b for 4 s (a laptop lid, a swap storm): alice's base0, at sim-a, streams, drives and stays hers
    throughout; when sim-b resumes, it rejoins the world as base1's sim, base1 streams again, and bob still owns it
    with the same epoch and drives it (no standby, no restart)."""
    common, probe, sim_a, sim_b = _two_shards(world, router, connect, procs)
    roles = SimRoles(probe)  # the roles the sims show (their role tokens)
    alice = World(client_config(world, router[1]), "alice", timeout=10.0)
    bob = World(client_config(world, router[1]), "bob", timeout=10.0)
    resumed = False
    try:
        b0, b1 = alice.robot("base0"), bob.robot("base1")
        for b in (b0, b1):
            b.wait_for("pose", timeout=20)
            b.request(timeout=10)
        epoch0, epoch1 = alice.ownership.record("base0").epoch, bob.ownership.record("base1").epoch
        gone: list[tuple[str, list[str]]] = []
        alice.on_robots_gone(lambda sim, robots: gone.append((sim, robots)))

        os.kill(sim_b.pid, signal.SIGSTOP)
        stopped = time.time_ns()
        x = b0.xy_theta[0]
        b0.twist(0.3, 0.0)
        wait_until(
            lambda: b0.xy_theta[0] > x + 0.1,
            timeout=20,
            what="base0 driving while sim-b is paused",
            seen=lambda: (b0.xy_theta, alice.events[-3:]),
        )
        b0.stop(timeout=10)
        # base0's poses keep coming for the whole pause (a condition, not a sleep: a pose stamped 4 s in)
        wait_until(
            lambda: b0.pose.header.wall_ns > stopped + 4_000_000_000,
            timeout=30,
            what="base0 streaming 4 s into the pause",
        )
        assert (
            b1.pose.header.wall_ns < stopped + 500_000_000
        )  # nothing from the paused sim meanwhile (the last in flight)
        os.kill(sim_b.pid, signal.SIGCONT)
        resumed = True
        cont = time.time_ns()
        wait_until(
            lambda: b1.pose.header.wall_ns > cont,
            timeout=30,
            what="base1 streaming again after SIGCONT",
            seen=lambda: procs.output(sim_b)[-800:],
        )
        x1 = b1.xy_theta[0]
        b1.twist(0.3, 0.0)  # faces -x
        wait_until(
            lambda: b1.xy_theta[0] < x1 - 0.1,
            timeout=20,
            what="bob driving base1 after the pause",
            seen=lambda: (b1.xy_theta, bob.events[-3:], procs.output(sim_b)[-800:]),
        )
        b1.stop(timeout=10)
        rec0, rec1 = alice.ownership.record("base0"), bob.ownership.record("base1")
        assert (rec0.owner, rec0.epoch, rec0.authority) == ("alice", epoch0, "sim-a"), rec0
        assert (rec1.owner, rec1.epoch, rec1.authority) == ("bob", epoch1, "sim-b"), rec1
        # 4 s is past the transport lease (2 s): the router dropped sim-b meanwhile and alice was told base1 went;
        # it is back in her world now, and her own robot never left it
        assert gone == [("sim-b", ["base1"])], gone
        wait_until(
            lambda: sorted(alice.robots()) == ["base0", "base1"],
            timeout=20,
            what="base1 back in alice's world",
            seen=alice.sims,
        )
        assert {(r.sim, r.role) for r in roles.shown} == {
            ("sim-a", "primary"),
            ("sim-b", "primary"),
        }  # nobody stepped down
    finally:
        if not resumed:
            os.kill(sim_b.pid, signal.SIGCONT)  # a paused process cannot be ended by SIGTERM
        alice.close()
        bob.close()


def test_when_the_scene_objects_sim_dies_another_shard_adopts_them_where_they_were(world, router, connect, procs):
    """sim-a (the first sim: base0 and the scene objects) is killed with no standby: sim-b, which mirrored the goal
    pointer's moves, serves the objects one term up, with the goal where alice last put it (no jump back to the
    scene's default); alice keeps base1 with its epoch and moves the goal again at sim-b."""
    common, probe, sim_a, sim_b = _two_shards(world, router, connect, procs)
    roles = SimRoles(probe)  # the roles the sims show (their role tokens)
    w = World(client_config(world, router[1]), "alice", timeout=10.0)
    try:
        b1 = w.robot("base1")
        b1.wait_for("pose", timeout=20)
        b1.request(timeout=10)
        epoch1 = w.ownership.record("base1").epoch
        goal = w.object("goal")
        goal.set_pose([2.0, 1.0, 0.0])
        wait_until(
            lambda: _goal_at(probe, world, "sim-a", (2.0, 1.0)),
            timeout=20,
            what="the goal moved at sim-a",
            seen=lambda: _parts(probe, world),
        )

        procs.kill(sim_a)
        wait_until(
            lambda: _goal_at(probe, world, "sim-b", (2.0, 1.0)),
            timeout=90,  # sim-a's going heard, the objects adopted: a whole run at load 20 took over 30 s
            what="sim-b serving the goal where it was",
            seen=lambda: (_parts(probe, world), procs.output(sim_b)[-800:]),
        )
        # the line is printed just after sim-b starts serving, so a query can see the goal before the line is out
        wait_until(
            lambda: (
                "no sim serves the scene objects any more; serving goal, target with my robots (term 2)"
                in procs.output(sim_b)
            ),
            timeout=20,
            what="sim-b saying it adopted the scene objects",
            seen=lambda: procs.output(sim_b)[-800:],
        )
        roles.wait("sim-b", "primary", term=2, timeout=20)  # its role shows the adoption's term
        r = subprocess.run(
            robofabric_cmd("own", "list", "--json", *common), capture_output=True, text=True, timeout=120
        )
        assert r.returncode == 0, r.stderr[-800:]
        auth = {rec["object"]: rec["authority"] for rec in json.loads(r.stdout)["records"]}
        assert auth == {"base1": "sim-b", "goal": "sim-b", "target": "sim-b"}, auth
        goal.set_pose([3.0, -1.0, 0.0])
        wait_until(
            lambda: _goal_at(probe, world, "sim-b", (3.0, -1.0)),
            timeout=20,
            what="the goal moved at sim-b",
            seen=lambda: _parts(probe, world),
        )
        wait_until(
            lambda: (w.ownership.record("base1") or b1.record).header.term == 2,
            timeout=20,
            what="base1's record at term 2",
        )
        rec = w.ownership.record("base1")
        assert (rec.owner, rec.epoch, rec.authority) == ("alice", epoch1, "sim-b"), rec
        x = b1.xy_theta[0]
        b1.twist(0.3, 0.0)
        wait_until(lambda: b1.xy_theta[0] < x - 0.1, timeout=20, what="base1 driving after the adoption")
        b1.stop(timeout=10)
    finally:
        w.close()


def _goal_at(fab, world: str, sim: str, xy: tuple[float, float]) -> bool:
    part = _parts(fab, world).get(sim)
    goal = next((o for o in part.objects if o.id == "goal"), None) if part is not None else None
    return goal is not None and abs(goal.position[0] - xy[0]) < 1e-6 and abs(goal.position[1] - xy[1]) < 1e-6
