"""IK: FK -> IK -> FK round trips (closed form, position only, numerical), singularities, refusals, a property test.

Targets come from FK of random in-limit joint vectors, so each one is reachable;
those whose flange lands inside the base column are refused by design and are
counted apart, not as failures.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from compute_peer.kinematics import (
    ArmModel,
    IKSolution,
    NoIKSolution,
    in_base_column,
    meca500_ik,
    solve,
)
from compute_peer.kinematics import ik as ik_module


@pytest.fixture(scope="module")
def arm():
    return ArmModel("meca500")


def _quat(m: pin.SE3) -> list[float]:
    q = pin.Quaternion(m.rotation)
    return [q.w, q.x, q.y, q.z]


def _in_column(arm, p) -> bool:
    return in_base_column(arm, p)


def _rot_err(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(pin.log3(a.T @ b)))


def _within(arm, q) -> bool:
    return bool(np.all(q >= arm.lower) and np.all(q <= arm.upper))


def _same_angles(a, b, tol=1e-6) -> bool:
    d = np.asarray(a) - np.asarray(b)
    return bool(np.all(np.abs(np.remainder(d + math.pi, 2 * math.pi) - math.pi) < tol))


@pytest.mark.slow
def test_closed_form_full_pose_round_trip(arm):
    rng = np.random.default_rng(10)
    n, ok, column, failures, candidates = 5000, 0, 0, [], 0
    for _ in range(n):
        q = rng.uniform(arm.lower, arm.upper)
        m = arm.fk(q)
        if _in_column(arm, m.translation):
            column += 1
            continue
        seed = rng.uniform(arm.lower, arm.upper)
        try:
            sol = solve(arm, m.translation, _quat(m), seed)
        except NoIKSolution as exc:
            failures.append((q.tolist(), str(exc)))
            continue
        got = arm.fk(sol.q)
        assert sol.solver == "closed_form" and _within(arm, sol.q)
        assert np.linalg.norm(got.translation - m.translation) <= 1e-6
        assert _rot_err(got.rotation, m.rotation) <= 1e-6
        assert sol.position_error <= 1e-9 and sol.orientation_error <= 1e-8
        # every candidate the closed form returns is in the limits and reaches the pose; nearest-first
        sols = meca500_ik(arm, m.translation, m.rotation, seed)
        assert len(sols) == sol.candidates and np.allclose(sols[0], sol.q)
        assert any(_same_angles(s, q) for s in sols)
        for s in sols:
            assert _within(arm, s)
            f = arm.fk(s)
            assert np.linalg.norm(f.translation - m.translation) <= 1e-9 and _rot_err(f.rotation, m.rotation) <= 1e-8
        candidates += len(sols)
        ok += 1
    rate = ok / (n - column)
    print(f"closed form: {ok}/{n - column} ({column} in the base column), {candidates / max(ok, 1):.2f} solutions/pose")
    for f in failures[:10]:
        print("FAILED", f)
    assert rate >= 0.999


def test_nearest_is_the_seed_itself(arm):
    rng = np.random.default_rng(11)
    for _ in range(1000):
        q = rng.uniform(arm.lower, arm.upper)
        m = arm.fk(q)
        sol = meca500_ik(arm, m.translation, m.rotation, q)[0]
        assert _same_angles(sol, q), (q, sol)


def test_position_only_round_trip(arm):
    rng = np.random.default_rng(12)
    n, ok, column, failures, solvers = 1000, 0, 0, [], {"closed_form": 0, "numerical": 0}
    for _ in range(n):
        q = rng.uniform(arm.lower, arm.upper)
        p = arm.fk(q).translation
        if _in_column(arm, p):
            column += 1
            continue
        seed = rng.uniform(arm.lower, arm.upper)
        try:
            sol = solve(arm, p, None, seed)
        except NoIKSolution as exc:
            failures.append((q.tolist(), str(exc)))
            continue
        assert _within(arm, sol.q) and sol.orientation_error == 0.0
        assert np.linalg.norm(arm.fk(sol.q).translation - p) <= 1e-6
        solvers[sol.solver] += 1
        ok += 1
    print(f"position only: {ok}/{n - column} ({column} in the base column), by solver {solvers}")
    for f in failures[:10]:
        print("FAILED", f)
    assert ok / (n - column) >= 0.999


def test_position_only_prefers_the_seed_orientation(arm):
    q = np.array([0.3, 0.2, -0.4, 0.5, 0.6, 0.7])
    sol = solve(arm, arm.fk(q).translation, seed=q)
    assert sol.solver == "closed_form" and _same_angles(sol.q, q)


@pytest.mark.slow
def test_numerical_round_trip_near_and_far_seeds(arm):
    rng = np.random.default_rng(13)
    n, ok, failures = 300, 0, []
    for i in range(n):
        q = rng.uniform(arm.lower, arm.upper)
        m = arm.fk(q)
        seed = (
            np.clip(q + rng.normal(0.0, 0.3, 6), arm.lower, arm.upper) if i % 2 else rng.uniform(arm.lower, arm.upper)
        )
        try:
            sol = solve(arm, m.translation, _quat(m), seed, method="numerical")
        except NoIKSolution as exc:
            failures.append((q.tolist(), str(exc)))
            continue
        got = arm.fk(sol.q)
        assert sol.solver == "numerical" and sol.candidates == 0 and _within(arm, sol.q)
        assert np.linalg.norm(got.translation - m.translation) <= 1e-6 and _rot_err(got.rotation, m.rotation) <= 1e-6
        ok += 1
    print(f"numerical: {ok}/{n}")
    for f in failures[:10]:
        print("FAILED", f)
    assert ok / n >= 0.99


def test_numerical_position_only(arm):
    rng = np.random.default_rng(14)
    for _ in range(50):
        q = rng.uniform(arm.lower, arm.upper)
        p = arm.fk(q).translation
        sol = solve(arm, p, seed=rng.uniform(arm.lower, arm.upper), method="numerical")
        assert np.linalg.norm(arm.fk(sol.q).translation - p) <= 1e-6 and sol.orientation_error == 0.0


def test_wrist_singularity_keeps_the_seed_q4(arm):
    q = np.array([0.4, 0.3, -0.5, 1.0, 0.0, -0.7])  # q5 = 0: only q4 + q6 matters
    m = arm.fk(q)
    seed = np.array([0.4, 0.3, -0.5, -0.6, 0.1, 0.0])
    sol = solve(arm, m.translation, _quat(m), seed)
    assert sol.q[3] == pytest.approx(-0.6, abs=1e-12)
    assert sol.q[3] + sol.q[5] == pytest.approx(0.3, abs=1e-9)
    got = arm.fk(sol.q)
    assert np.linalg.norm(got.translation - m.translation) <= 1e-9 and _rot_err(got.rotation, m.rotation) <= 1e-8


def test_shoulder_singularity_keeps_the_seed_q1(arm):
    # tool horizontal along +x with the wrist centre on the J1 axis, 0.3 m up
    rot = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    p = np.array([0.070, 0.0, 0.3])
    for q1 in (0.4, -1.2):
        seed = np.array([q1, 0.2, -0.3, 0.0, 0.5, 0.0])
        sols = meca500_ik(arm, p, rot, seed)
        assert all(_same_angles([s[0]], [q1]) or _same_angles([s[0]], [q1 + math.pi]) for s in sols)
        assert sols[0][0] == pytest.approx(q1, abs=1e-12)


def test_j6_at_180_degrees_gives_both_twins(arm):
    q = np.array([0.2, 0.1, -0.3, 0.4, 0.7, math.pi])
    m = arm.fk(q)
    sols = meca500_ik(arm, m.translation, m.rotation, q)
    q6 = sorted(s[5] for s in sols if _same_angles(s[:5], q[:5]))
    assert q6 == pytest.approx([-math.pi, math.pi], abs=1e-9)
    assert all(_within(arm, s) for s in sols)


def test_unreachable_targets_are_refused_with_reasons(arm):
    with pytest.raises(NoIKSolution, match=r"out of reach: distance to shoulder 1\.\d+ m > max 0\.33\d+ m"):
        solve(arm, [1.0, 0.0, 0.3])
    with pytest.raises(NoIKSolution, match=r"out of reach: wrist centre"):
        solve(arm, [1.0, 0.0, 0.3], [1.0, 0.0, 0.0, 0.0])
    with pytest.raises(NoIKSolution, match=r"out of reach"):
        solve(arm, [0.0, 0.5, 0.3], [1.0, 0.0, 0.0, 0.0], method="closed_form")
    for method in ("auto", "numerical"):
        with pytest.raises(NoIKSolution, match=r"inside the base column: 0\.010 m from its axis < radius 0\.060 m"):
            solve(arm, [0.01, 0.0, 0.05], method=method)
    assert in_base_column(arm, [0.0, 0.05, 0.0]) and not in_base_column(arm, [0.0, 0.05, 0.1])
    # within reach, impossible orientation: the tool pointing straight up just over the base
    with pytest.raises(
        NoIKSolution, match=r"all 8 solutions violate joint limits: J5 at 146\.7° \(limits -115\.\.115°\)"
    ):
        solve(arm, [0.1, 0.0, 0.1], [1.0, 0.0, 0.0, 0.0])
    with pytest.raises(NoIKSolution, match=r"did not converge from 25 starts: best residual .* m, .* rad \(J\d at its"):
        solve(arm, [0.1, 0.0, 0.1], [1.0, 0.0, 0.0, 0.0], method="numerical")


@pytest.mark.parametrize(
    ("position", "quaternion", "seed", "what"),
    [
        ([math.nan, 0.0, 0.3], None, None, "not finite"),
        ([0.2, 0.0, math.inf], None, None, "not finite"),
        ([0.2, 0.0], None, None, "expected 3"),
        ([[0.2, 0.0, 0.3]], None, None, "expected 3"),
        ("123", None, None, "expected 3 numbers"),
        (np.zeros((3, 1)), None, None, "shape"),
        ("abc", None, None, "expected 3 numbers"),
        ([0.2, 0.0, 0.3], [1.0, 0.0, 0.0], None, "expected 4"),
        ([0.2, 0.0, 0.3], [0.0, 0.0, 0.0, 0.0], None, "too small"),
        ([0.2, 0.0, 0.3], [1.0, math.nan, 0.0, 0.0], None, "not finite"),
        ([0.2, 0.0, 0.3], None, [0.0] * 5, "expected 6"),
        ([0.2, 0.0, 0.3], None, [0.0] * 5 + [math.nan], "not finite"),
    ],
)
def test_malformed_input_is_a_plain_value_error(arm, position, quaternion, seed, what):
    with pytest.raises(ValueError, match=what) as info:
        solve(arm, position, quaternion, seed)
    assert not isinstance(info.value, NoIKSolution)


def test_methods_and_registry(arm, monkeypatch):
    with pytest.raises(ValueError, match="method 'fast'"):
        solve(arm, [0.19, 0.0, 0.308], method="fast")
    q = np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    m = arm.fk(q)
    monkeypatch.delitem(ik_module.CLOSED_FORMS, "meca500")
    with pytest.raises(ValueError, match="no closed-form IK"):
        solve(arm, m.translation, _quat(m), q, method="closed_form")
    sol = solve(arm, m.translation, _quat(m), q)  # auto: numerical when the type has no closed form
    assert sol.solver == "numerical" and np.linalg.norm(arm.fk(sol.q).translation - m.translation) <= 1e-6


def test_solution_is_frozen(arm):
    sol = solve(arm, [0.19, 0.0, 0.308], [math.cos(math.pi / 4), 0.0, math.sin(math.pi / 4), 0.0])
    assert isinstance(sol, IKSolution) and _same_angles(sol.q, np.zeros(6)) and sol.candidates >= 1
    with pytest.raises(ValueError):
        sol.q[0] = 1.0
    with pytest.raises(AttributeError):
        sol.solver = "x"  # type: ignore[misc]
    # an unnormalised quaternion is normalised, not refused
    assert np.allclose(solve(arm, [0.19, 0.0, 0.308], [2.0, 0.0, 2.0, 0.0]).q, sol.q)


_ARM = ArmModel("meca500")
_coord = st.floats(-0.4, 0.4, allow_nan=False)
_quats = st.one_of(
    st.none(),
    st.lists(st.floats(-1.0, 1.0, allow_nan=False), min_size=4, max_size=4).filter(
        lambda v: math.sqrt(sum(x * x for x in v)) > 1e-3
    ),
)


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(x=_coord, y=_coord, z=st.floats(-0.1, 0.5, allow_nan=False), quat=_quats)
def test_solve_returns_a_valid_solution_or_refuses(x, y, z, quat):
    arm = _ARM
    try:
        sol = solve(arm, [x, y, z], quat)
    except NoIKSolution as exc:
        assert str(exc)
        return
    assert _within(arm, sol.q)
    got = arm.fk(sol.q)
    assert np.linalg.norm(got.translation - [x, y, z]) <= 1e-6
    if quat is not None:
        qn = np.asarray(quat) / np.linalg.norm(quat)
        target = pin.Quaternion(qn[0], qn[1], qn[2], qn[3]).toRotationMatrix()
        assert _rot_err(got.rotation, target) <= 1e-6


def test_tilted_tool_frames_are_rotations_pointing_where_asked():
    import math

    from compute_peer.kinematics.ik import TILTS, tool_frame

    for elevation, azimuth in TILTS + ((90.0, 0.0), (-90.0, 30.0)):
        a, e = math.radians(azimuth), math.radians(elevation)
        r = np.array(tool_frame(a, e))
        assert np.allclose(r.T @ r, np.eye(3), atol=1e-12) and np.isclose(np.linalg.det(r), 1.0)
        assert np.allclose(r[:, 2], [math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
