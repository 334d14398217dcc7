"""An arm brought from a URDF (``robots add``, example-robot-data's Panda: 7 joints) in one world with the
Meca500 and the Reeman base, end to end over Zenoh: the sim builds and describes it, streams its joints under
the URDF's names, the compute peer learns it from the world and solves its IK, the user's move puts the sim's
flange where IK said."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import robots
from compute_peer.kinematics.arm import PlacedArm
from compute_peer.kinematics.model import ArmModel
from compute_peer.kinematics.service import KinematicsService
from robofabric.testing import client_config, example_robot_urdf, wait_until
from robots.urdf import parse
from robots.urdf_import import install
from sim_peer.serving.peer import SimPeer
from sim_peer.physics.world import SimWorld
from user_peer.api import World

PANDA = "panda_description/urdf/panda.urdf"


@pytest.fixture
def panda_installed(tmp_path, monkeypatch):
    folder = tmp_path / "robots"
    monkeypatch.setenv(robots.description.ENV_PATH, str(folder))
    return install(example_robot_urdf(PANDA), into=folder, name="panda")


def test_the_sim_builds_a_world_with_the_meca500_the_panda_and_a_base(panda_installed):
    w = SimWorld("combined", ["panda:p1@1.5,-1.5"])
    assert set(w.robots) == {"arm1", "base1", "p1"}
    p1 = w.robot("p1")
    assert type(p1).__name__ == "ArmRobot" and p1.desc.dof == 7
    # the fingers are welded: the Panda adds its 7 joints only
    assert w.model.nq == w.robot("arm1").desc.dof + 7 + len(w.robot("base1").desc.base_joints)
    w.reset()
    # the reset pose is zero clamped into the limits: the Panda's J4 cannot be 0, it rests at its upper limit
    assert w.state("p1")["q"][3] == pytest.approx(-0.0698)


@pytest.mark.slow  # a sim, a compute service and a user over a router, for seconds
def test_a_user_moves_the_panda_through_the_compute_peers_ik(panda_installed, world, router, connect):
    names = tuple(
        j.name
        for j in parse(panda_installed.directory.joinpath("panda.urdf").read_text()).joints
        if j.type == "revolute"
    )
    sim_world = SimWorld("combined", ["panda:p1@1.5,-1.5"])
    with (
        SimPeer(connect("sim", "sim-urdf"), sim_world, rates={"joints": 50, "pose": 50, "scan": 10}),
        KinematicsService(connect("compute", "compute-urdf")) as svc,
    ):
        w = World(client_config(world, router[1]), "alice", timeout=10.0)
        try:
            assert {"arm1", "base1", "p1"} <= set(w.robots())  # info() waits for the sim's description
            p1 = w.robot("p1")
            assert p1.type == "panda" and p1.entry.joint_names == names  # the URDF's joint names, in its order
            js = p1.wait_for("joints", timeout=10)
            assert js.names == names and len(js.q) == 7
            # what the ROS 2 bridge and `export --to ros2` make of it: joint_states named as in the URDF
            from sensor_msgs.msg import JointState as RosJointState

            from user_peer.ros2 import direct

            assert direct.joint_state(RosJointState(), "p1", js, 1).name == list(names)
            # a reachable pose, from FK of known joints at the arm's place in this world
            placed = PlacedArm(ArmModel("panda"), sim_world.placements["p1"].pose)
            q = np.array([0.4, 0.3, -0.2, -1.6, 0.3, 1.9, 0.5])
            pos, quat = placed.fk(q)
            sol = p1.ik(pos, quat)
            assert "p1" in svc.arms and len(sol) == 7
            np.testing.assert_allclose(placed.fk(sol)[0], pos, atol=1e-6)
            p1.move_joints(sol, tol=1e-3, timeout=20)
            # the sim (MuJoCo, its own compile of the URDF) puts the flange where the compute peer (Pinocchio) said
            flange = wait_until(
                lambda: _near(p1.flange, pos), timeout=10, what="the sim's flange at the target", seen=lambda: p1.flange
            )
            got = pin.Quaternion(float(flange.quaternion[0]), *map(float, flange.quaternion[1:])).toRotationMatrix()
            want = pin.Quaternion(float(quat[0]), *map(float, quat[1:])).toRotationMatrix()
            assert np.linalg.norm(pin.log3(got.T @ want)) < 1e-2
        finally:
            w.close()


def _near(pose, pos, tol: float = 2e-3):
    return pose if pose is not None and np.linalg.norm(np.asarray(pose.position) - pos) < tol else None


@pytest.mark.slow  # a sim with its authority, a compute service and a user over a router; a scenario of seconds
@pytest.mark.parametrize("robot", ["panda", "ur5"])
def test_the_papers_test_a_runs_on_an_arm_from_a_urdf(robot, tmp_path, monkeypatch, world, router, connect):
    """Test A (the target sphere on a circle, IK, apply, the sim's flange on each target) on the Panda and the
    UR5, with the sim's ownership authority: its circle (around a point 19 cm in front of the base, 25 cm up,
    chosen for the Meca500) is within both arms' reach."""
    from ownership import Authority
    from user_peer import scenarios

    folder = tmp_path / "robots"
    monkeypatch.setenv(robots.description.ENV_PATH, str(folder))
    install(
        example_robot_urdf({"panda": PANDA, "ur5": "ur_description/urdf/ur5_robot.urdf"}[robot]),
        into=folder,
        name=robot,
    )
    sim_fab = connect("sim", "sim-urdf-a")
    sim_world = SimWorld("combined", [f"{robot}:a2@1.5,-1.5"])
    authority = Authority(
        sim_fab,
        objects={"a2": "exclusive", "arm1": "exclusive", "base1": "exclusive", "target": "scene", "goal": "scene"},
    ).start()
    with (
        SimPeer(sim_fab, sim_world, gate=authority, rates={"joints": 50, "pose": 50, "scan": 10}),
        KinematicsService(connect("compute", "compute-urdf-a")),
    ):
        w = World(client_config(world, router[1]), "alice", timeout=10.0)
        try:
            res = scenarios.test_a(w, arm_id="a2", points=4, hold=0.0)
            assert res.ok, res.lines
            assert res.figures["targets"] == 4 and res.figures["max_error_mm"] <= 5.0
        finally:
            w.close()
            authority.close()
