import numpy as np
import pinocchio as pin
import pytest

from compute_peer.kinematics import ArmModel, NoIKSolution


@pytest.fixture(scope="module")
def arm():
    return ArmModel("meca500")


def _random_q(arm, rng):
    return rng.uniform(arm.lower, arm.upper)


def test_zero_pose_flange_matches_issue_3(arm):
    assert np.allclose(arm.fk(np.zeros(6)).translation, [0.190, 0.0, 0.308], atol=1e-9)


def test_jacobian_matches_pinocchio_and_finite_differences(arm):
    rng = np.random.default_rng(1)
    for _ in range(20):
        q = _random_q(arm, rng)
        j = arm.jacobian(q)
        pin.computeJointJacobians(arm.model, arm.data, q)
        jp = pin.getFrameJacobian(arm.model, arm.data, arm.frame_id, pin.LOCAL_WORLD_ALIGNED)
        assert np.allclose(j, jp, atol=1e-9)
        h = 1e-7
        for i in range(6):
            dq = np.zeros(6)
            dq[i] = h
            fd = (arm.fk(q + dq).translation - arm.fk(q - dq).translation) / (2 * h)
            assert np.allclose(j[:3, i], fd, atol=1e-6)


def test_ik_position_round_trip(arm):
    rng = np.random.default_rng(2)
    for _ in range(50):
        q = _random_q(arm, rng)
        target = arm.fk(q).translation
        sol = arm.ik_position(target, q + rng.normal(0, 0.05, 6))
        assert np.linalg.norm(arm.fk(sol).translation - target) <= 1e-6
        assert np.all(sol >= arm.lower) and np.all(sol <= arm.upper)


def test_unreachable_refused(arm):
    with pytest.raises(NoIKSolution):
        arm.ik_position([2.0, 0.0, 0.3], np.zeros(6))
    with pytest.raises(NoIKSolution):
        arm.ik_position([np.nan, 0.0, 0.3], np.zeros(6))
