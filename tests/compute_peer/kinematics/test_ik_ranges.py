"""IK checks its target's range before computing: a target beyond the arm's longest reach is refused at once with a
readable distance (the numerical method tried 25 starts at 1e9 m; the closed form printed a 300-digit distance for
1e300)."""

from __future__ import annotations

import pytest

from compute_peer.kinematics import ArmModel, NoIKSolution, solve
from compute_peer.kinematics.ik import longest_reach


@pytest.fixture(scope="module")
def arm():
    return ArmModel("meca500")


def test_the_longest_reach_bounds_every_pose_of_the_arm(arm):
    import numpy as np

    reach = longest_reach(arm)
    rng = np.random.default_rng(7)
    lo, hi = arm.model.lowerPositionLimit, arm.model.upperPositionLimit
    for _ in range(200):
        q = rng.uniform(lo, hi)
        assert np.linalg.norm(arm.fk(q).translation) <= reach + 1e-9


@pytest.mark.parametrize("target", [(1e300, 0.0, 0.0), (1e9, 0.0, 0.1), (5.0, 0.0, 0.2)])
def test_a_target_beyond_the_reach_is_refused_before_the_numerical_solver(arm, target):
    with pytest.raises(
        NoIKSolution,
        match=r"out of reach: the target is [0-9.e+]+ m from the arm's base, beyond its longest reach of 0\.4980 m",
    ):
        solve(arm, target, method="numerical")


@pytest.mark.parametrize("method", ["auto", "closed_form", "casadi"])
def test_every_method_says_out_of_reach_in_a_line_a_person_reads(arm, method):
    with pytest.raises(NoIKSolution, match="out of reach") as info:
        solve(arm, (1e300, 0.0, 0.0), method=method)
    assert len(str(info.value)) < 120, str(info.value)


def test_a_reachable_target_still_solves(arm):
    assert solve(arm, (0.2, 0.0, 0.3)).position_error < 1e-6
