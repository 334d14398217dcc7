"""A third robot type added the way a third party would: a folder on ROBOFABRIC_ROBOTS_PATH with its MJCF,
its description and its hooks (tests/sim_peer/plugin_robots/planar2/), and a scene that holds it. Nothing in
sim_peer knows about it: the world builds it from its description, the peer serves it from its hooks."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

import robots
import sim_peer.serving.peer
from fabric import keys
from fabric.interfaces import Command, Event, JointState, JointTarget, Pose, Twist, WorldInfo
from robofabric.testing import wait_until
from ownership import Authority, OwnershipClient
from sim_peer.serving.peer import SimPeer
from sim_peer.robot import HOOKS, SimRobot, Stream
from sim_peer.physics.world import SimWorld, WorldError

PLUGINS = Path(__file__).parent / "plugin_robots"
L1, L2, BASE_Z = 0.30, 0.25, 0.75 + 0.05  # link lengths; the shoulder sits 5 cm above the spawn height


@pytest.fixture
def plugin_path(monkeypatch):
    monkeypatch.setenv(robots.description.ENV_PATH, str(PLUGINS))
    return PLUGINS


def tip(q1: float, q2: float, x0: float = 0.0, y0: float = 0.0) -> np.ndarray:
    return np.array(
        [x0 + L1 * math.cos(q1) + L2 * math.cos(q1 + q2), y0 + L1 * math.sin(q1) + L2 * math.sin(q1 + q2), BASE_Z]
    )


def test_the_world_builds_and_steps_a_robot_type_from_its_description_and_hooks(plugin_path):
    assert "planar2" in robots.available_robots() and "planar_cell" in robots.available_scenes()
    w = SimWorld("planar_cell")
    p1 = w.robot("p1")
    assert type(p1).__name__ == "Planar2Arm" and isinstance(p1, SimRobot) and set(w.robots) == {"p1", "arm1"}
    assert not w.dynamic  # its two hinges are its own (kinematic_dofs): nothing left for MuJoCo to integrate
    assert p1.commands()["joints"](JointTarget(np.array([0.6, -0.9]))) is None
    w.step(int(1.0 / w.dt))  # 0.9 rad at 3 rad/s and 0.6 at 2 rad/s: there within 0.3 s
    w.sync()
    np.testing.assert_allclose(w.data.qpos[p1.qadr], [0.6, -0.9], atol=1e-12)
    np.testing.assert_allclose(w.data.site_xpos[p1.tip], tip(0.6, -0.9), atol=1e-9)  # the MJCF agrees with the geometry
    assert w.state("p1")["q"] == pytest.approx([0.6, -0.9]) and not p1.moving
    w.reset()
    assert p1.q.tolist() == [0.0, 0.0]
    # robot placed from the command line like any other type
    w2 = SimWorld("combined", ["planar2:p2@-2,1"])
    assert type(w2.robot("p2")).__name__ == "Planar2Arm" and w2.placements["p2"].pose[:2] == (-2.0, 1.0)


def test_a_standby_carries_the_new_type_on_through_its_snapshot_and_restore_hooks(plugin_path):
    from sim_peer.physics import capture
    from fabric.interfaces import WorldState

    w = SimWorld("planar_cell")
    w.robot("p1").commands()["joints"](JointTarget(np.array([1.2, 0.4])))
    w.step(100)  # on its way: 0.2 s at 2 rad/s
    t, steps, states, objects = capture.capture(w)
    assert {s.id for s in states} == {"p1", "arm1"}
    w2 = SimWorld("planar_cell")
    capture.restore(w2, WorldState(t, steps, states, objects))
    p2 = w2.robot("p1")
    np.testing.assert_allclose(p2.q, w.robot("p1").q)
    np.testing.assert_allclose(p2.target, [1.2, 0.4])
    assert 0 < p2.q[0] < 1.2  # mid-move, not at either end
    w.step(500)
    w2.step(500)
    np.testing.assert_allclose(w2.robot("p1").q, w.robot("p1").q, atol=1e-12)  # both went on the same way


def test_a_bad_hooks_reference_is_a_world_error_naming_the_type(plugin_path, tmp_path, monkeypatch):
    bad = tmp_path / "broken"
    bad.mkdir()
    (bad / "broken.xml").write_text((PLUGINS / "planar2" / "planar2.xml").read_text())
    toml = (PLUGINS / "planar2" / "robot.toml").read_text().replace('name = "planar2"', 'name = "broken"')
    toml = toml.replace("planar2.xml", "broken.xml")
    (bad / "robot.toml").write_text(toml.replace("hooks.py:Planar2Arm", "hooks.py:Nope"))
    (bad / "hooks.py").write_text("class Nope:\n    pass\n")
    monkeypatch.setenv(robots.description.ENV_PATH, f"{tmp_path}")
    with pytest.raises(WorldError, match="broken.*not a sim_peer.robot.SimRobot subclass"):
        SimWorld("combined", ["broken:b1@-2,0"])
    (bad / "hooks.py").write_text(
        "from sim_peer.robot import SimRobot\nclass Nope(SimRobot):\n    def after_substep(self, physics):\n        pass\n"
    )
    (bad / "robot.toml").write_text(toml.replace("hooks.py:Planar2Arm", "hooks2.py:Nope"))
    (bad / "hooks2.py").write_text((bad / "hooks.py").read_text())
    with pytest.raises(WorldError, match="after_substep looks like a hook"):
        SimWorld("combined", ["broken:b1@-2,0"])


def test_the_peer_tests_no_robot_kind():
    """Kinds are the robots' business (their hooks); the peer loops over hooks. (It may tell its own
    commands apart, as the owner-lost ``Halt`` from a user's, but never a robot's class or kind.)"""
    src = Path(sim_peer.serving.peer.__file__).read_text()
    assert not re.search(r"isinstance\([^,]*robot|kind ==|ArmRobot|MobileRobot", src)
    assert HOOKS == ("describe", "initialize", "before_step", "after_step", "streams", "commands")
    assert Stream("joints", "joints", lambda physics: None).positions is False


def test_the_third_robot_type_is_described_streamed_and_commanded_by_its_owner(plugin_path, world, connect):
    sim_fab = connect("sim", "sim-plugin")
    sim_world = SimWorld("planar_cell")
    authority = Authority(sim_fab, objects={"p1": "exclusive", "arm1": "exclusive", "target": "scene"}).start()
    peer = SimPeer(sim_fab, sim_world, gate=authority, rates={"joints": 50, "pose": 50, "scan": 20}).start()
    fab = connect("user", "alice")
    alice = OwnershipClient(fab, "alice", renew_s=0.1, timeout=10.0).start()
    try:
        # the world description lists it, from its hooks' describe()
        info = wait_until(lambda: _world_info(fab, world), timeout=20, what="srv/world answered")
        p1 = info.robot("p1")
        assert (p1.type, p1.kind, p1.joint_names) == ("planar2", "arm", ("shoulder", "elbow"))
        np.testing.assert_allclose(p1.max_speed, [2.0, 3.0])
        np.testing.assert_allclose(p1.pose, [0.0, 0.0, 0.75, 0.0])
        assert p1.flange_site == "tip" and info.robot("arm1").type == "meca500"

        # its joints stream, and its tip pose with them
        latest: dict[str, object] = {}
        events: list[Event] = []
        fab.subscribe(keys.robot_joints(world, "p1"), lambda k, m: latest.__setitem__("joints", m), expected=JointState)
        fab.subscribe(keys.robot_pose(world, "p1"), lambda k, m: latest.__setitem__("pose", m), expected=Pose)
        fab.subscribe(keys.event_all(world), lambda k, e: events.append(e), expected=Event)
        js = wait_until(lambda: latest.get("joints"), timeout=10, what="p1 joints")
        assert js.names == ("shoulder", "elbow") and js.header.source == "sim-plugin"
        wait_until(lambda: latest.get("pose"), timeout=10, what="p1 tip pose")

        # a command from someone who does not own it is refused by the authority
        fab.publish(
            keys.robot_cmd(world, "p1", "joints", "alice"), Command("alice", 1, JointTarget(np.array([0.5, 0.5])))
        )
        wait_until(
            lambda: any(e.kind == "reject" and e.object == "p1" for e in events),
            timeout=10,
            what="non-owner refused",
            seen=lambda: events[-5:],
        )
        assert peer.last_state("p1")["target"] == [0.0, 0.0]

        # its owner's joint command moves it
        wait_until(
            lambda: alice.record("p1") is not None, timeout=20, what="p1's ownership record", seen=alice.snapshot
        )
        out = alice.request("p1")
        assert out.outcome == "granted", out
        goal = np.array([0.7, -1.1])
        fab.publish(
            keys.robot_cmd(world, "p1", "joints", "alice"), Command("alice", alice.epoch("p1"), JointTarget(goal))
        )

        def arrived() -> bool:
            m = latest.get("joints")
            return isinstance(m, JointState) and np.allclose(m.q, goal, atol=1e-9) and not m.dq.any()

        wait_until(arrived, timeout=15, what="p1 at its target", seen=lambda: (latest.get("joints"), events[-3:]))
        wait_until(
            lambda: np.allclose(latest["pose"].position, tip(*goal), atol=1e-9),
            timeout=10,
            what="p1 tip pose at the target",
            seen=lambda: latest.get("pose"),
        )
        # a command kind its hooks do not list is refused as unsupported
        fab.publish(keys.robot_cmd(world, "p1", "twist", "alice"), Command("alice", alice.epoch("p1"), Twist(0.1, 0.0)))
        ev = wait_until(
            lambda: next((e for e in events if e.reason == "unsupported" and e.object == "p1"), None),
            timeout=10,
            what="unsupported twist",
            seen=lambda: events[-5:],
        )
        assert ev.user == "alice" and "joints" in ev.data["detail"]
    finally:
        alice.close()
        peer.close()
        authority.close()


def _world_info(fab, world) -> WorldInfo | None:
    from fabric.interfaces import ServiceError

    try:
        return fab.rpc.call(keys.srv(world, "world"), timeout=1.0)
    except ServiceError:
        return None
