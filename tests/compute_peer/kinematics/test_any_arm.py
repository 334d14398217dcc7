"""Kinematics of arms brought from a URDF (``robots add``): example-robot-data's UR5 (6 joints) and Panda (7
joints, a gripper whose fingers are held). IK with position and orientation inside the limits, nearest to the
seed, an honest refusal when out of reach; the Jacobian and the paper's Eq. 7 speeds for N joints."""

from __future__ import annotations

import numpy as np
import pytest

import robots
from compute_peer.kinematics.arm import PlacedArm
from compute_peer.kinematics.ik import solve
from compute_peer.kinematics.model import ArmModel, NoIKSolution
from robofabric.bench.ik_arm import measure_arm
from robofabric.testing import example_robot_urdf
from robots.urdf_import import install

ARMS = {"ur5": "ur_description/urdf/ur5_robot.urdf", "panda": "panda_description/urdf/panda.urdf"}


@pytest.fixture(scope="module")
def arms(tmp_path_factory) -> dict[str, ArmModel]:
    folder = tmp_path_factory.mktemp("robots")
    mp = pytest.MonkeyPatch()
    mp.setenv(robots.description.ENV_PATH, str(folder))
    for name, rel in ARMS.items():
        install(example_robot_urdf(rel), into=folder, name=name)
    yield {name: ArmModel(name) for name in ARMS}
    mp.undo()


@pytest.mark.slow  # 2 x 3 x 200 solves: seconds
@pytest.mark.parametrize("name", list(ARMS))
def test_ik_solves_99_percent_of_200_random_reachable_poses_within_1_mm_and_1_mrad(arms, name):
    result = measure_arm(name, 200, seed=0)
    assert result["joints"] == {"ur5": 6, "panda": 7}[name]
    for key in ("full_far", "full_near", "position"):
        assert result[key]["success"] >= 0.99, (key, result[key])


@pytest.mark.parametrize("name", list(ARMS))
def test_a_full_pose_round_trip_lands_on_the_seed_when_it_is_the_answer(arms, name):
    arm = arms[name]
    rng = np.random.default_rng(11)
    n = arm.model.nq
    for _ in range(5):
        q = rng.uniform(arm.lower, arm.upper)
        m = arm.fk(q)
        placed = PlacedArm(arm, (1.0, -0.5, 0.75, 0.4))
        pos, quat = placed.fk(q)
        sol = placed.ik(pos, quat, q + 0.02)  # a seed a hair off: the answer nearest it is q itself
        assert sol.solver == "numerical" and np.max(np.abs(sol.q - q)) < 0.01  # the seed's branch, not another one
        if n == 6:  # the UR5's answers are isolated: q exactly; the Panda's 7th joint leaves a curve of them
            assert np.allclose(sol.q, q, atol=1e-6)
        assert np.all(sol.q >= arm.lower) and np.all(sol.q <= arm.upper)
        np.testing.assert_allclose(arm.fk(sol.q).translation, m.translation, atol=1e-6)


@pytest.mark.parametrize("name", list(ARMS))
def test_an_unreachable_target_is_refused_with_the_reason(arms, name):
    arm = arms[name]
    with pytest.raises(NoIKSolution, match="out of reach: .* beyond its longest reach"):  # refused before solving
        solve(arm, [2.5, 0.0, 0.3], None, None)
    with pytest.raises(ValueError, match="has no closed-form IK"):
        solve(arm, [0.4, 0.0, 0.3], None, None, method="closed_form")  # the closed form stays the Meca500's


@pytest.mark.parametrize("name", list(ARMS))
def test_the_jacobian_and_eq7_speeds_take_n_joints(arms, name):
    arm = arms[name]
    placed = PlacedArm(arm, (0.0, 0.0, 0.0, 0.0))
    n = arm.model.nq
    rng = np.random.default_rng(2)
    q = rng.uniform(arm.lower, arm.upper)
    dq = rng.normal(0.0, 0.5, n)
    j, twist, speeds = placed.jacobian(q, dq)
    assert j.shape == (6, n) and speeds.shape == (n,)
    np.testing.assert_allclose(speeds, np.linalg.norm(j, axis=0) * np.abs(dq))
    h = 1e-6  # the linear rows are the flange's velocity: a finite difference of FK
    v = (arm.fk(q + h * dq).translation - arm.fk(q - h * dq).translation) / (2 * h)
    np.testing.assert_allclose(twist[:3], v, atol=1e-6)
    import pinocchio as pin  # and the whole of it is Pinocchio's own, in the world-aligned frame

    ref = pin.computeFrameJacobian(arm.model, arm.data, q, arm.frame_id, pin.LOCAL_WORLD_ALIGNED)
    np.testing.assert_allclose(j, ref, atol=1e-9)


def test_a_description_listing_fewer_joints_than_its_urdf_holds_the_others_at_zero(arms, tmp_path, monkeypatch):
    """A hand-written robot.toml may name the original Panda URDF, fingers and all (9 coordinates): the model is
    its 7 listed joints, the fingers held at zero, and agrees with the type `robots add` wrote."""
    panda = robots.installed("panda")
    folder = tmp_path / "handmade"
    folder.mkdir()
    manifest = panda.directory.joinpath("robot.toml").read_text()
    manifest = manifest.replace('urdf = "panda.urdf"', f'urdf = "{example_robot_urdf(ARMS["panda"])}"')
    manifest = manifest.replace('mjcf = "panda.xml"', f'mjcf = "{panda.mjcf_path}"')
    (folder / "robot.toml").write_text(manifest)
    hand = ArmModel(str(folder))
    assert hand.model.nq == 7 and tuple(hand.model.names)[1:] == panda.joint_names
    q = np.random.default_rng(8).uniform(hand.lower, hand.upper)
    assert np.allclose(hand.fk(q).homogeneous, arms["panda"].fk(q).homogeneous, atol=1e-12)
    (folder / "robot.toml").write_text(
        manifest.replace('"panda_joint1", "panda_joint2"', '"panda_joint2", "panda_joint1"')
    )
    with pytest.raises(ValueError, match="not the description's"):
        ArmModel(str(folder))


def test_a_prismatic_joints_column_is_its_axis_and_no_turn(tmp_path, monkeypatch):
    """Eq. 4-6 for a prismatic joint: [z; 0]. A lift, a turn, a telescope: the written-out Jacobian is Pinocchio's."""
    import pinocchio as pin

    def joint(name: str, kind: str, parent: str, child: str, xyz: str, axis: str, lo: float, hi: float) -> str:
        return (
            f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{xyz}"/><axis xyz="{axis}"/><limit lower="{lo}" upper="{hi}" velocity="1"/></joint>'
        )

    src = tmp_path / "lift.urdf"
    src.write_text(
        '<robot name="lift">'
        + "".join(f'<link name="l{i}"/>' for i in range(4))
        + joint("lift", "prismatic", "l0", "l1", "0 0 0.1", "0 0 1", 0.0, 0.5)
        + joint("turn", "revolute", "l1", "l2", "0.1 0 0", "0 1 0", -1.5, 1.5)
        + joint("reach", "prismatic", "l2", "l3", "0.2 0 0", "0.6 0 0.8", -0.1, 0.1)
        + "</robot>"
    )
    assert install(src, into=tmp_path / "robots").arm.joints == (
        "lift",
        "turn",
    )  # by default a prismatic end is a finger
    made = install(src, into=tmp_path / "robots", tip="l3", replace=True)
    arm = ArmModel(str(made.directory))
    assert made.arm.joints == ("lift", "turn", "reach") and arm.model.nq == 3
    q = np.array([0.2, 0.7, 0.05])
    ref = pin.computeFrameJacobian(arm.model, arm.data, q, arm.frame_id, pin.LOCAL_WORLD_ALIGNED)
    j = arm.jacobian(q)
    np.testing.assert_allclose(j, ref, atol=1e-12)
    np.testing.assert_allclose(j[:, 0], [0, 0, 1, 0, 0, 0], atol=1e-12)
