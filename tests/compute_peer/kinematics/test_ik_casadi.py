"""CasADi + IPOPT IK: the symbolic FK against Pinocchio, round trips, the seed, refusals, another arm.

Targets come from FK of random in-limit joint vectors (reachable); those in the
base column are skipped (``solve`` refuses them by design, for every method).
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from compute_peer.kinematics import ArmModel, NoIKSolution, in_base_column, solve
from compute_peer.kinematics.casadi_ik import casadi_ik, symbolic_fk
from robots.description import ENV_PATH


@pytest.fixture(scope="module")
def arm():
    return ArmModel("meca500")


def _quat(m: pin.SE3) -> list[float]:
    q = pin.Quaternion(m.rotation)
    return [q.w, q.x, q.y, q.z]


def _rot_err(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(pin.log3(a.T @ b)))


def _within(arm, q) -> bool:
    return bool(np.all(q >= arm.lower) and np.all(q <= arm.upper))


def _targets(arm, n: int, rng: np.random.Generator) -> list[tuple[np.ndarray, pin.SE3]]:
    out = []
    while len(out) < n:
        q = rng.uniform(arm.lower, arm.upper)
        m = arm.fk(q)
        if not in_base_column(arm, m.translation):
            out.append((q, m))
    return out


def _fk_matches(arm, n: int, rng: np.random.Generator) -> None:
    fk = symbolic_fk(arm)
    for _ in range(n):
        q = rng.uniform(arm.lower, arm.upper)
        p, r = fk(q)
        m = arm.fk(q)
        assert np.abs(np.asarray(p).ravel() - m.translation).max() <= 1e-12
        assert np.abs(np.asarray(r) - m.rotation).max() <= 1e-12


def test_symbolic_fk_equals_pinocchio(arm):
    _fk_matches(arm, 200, np.random.default_rng(0))


@pytest.mark.slow
def test_full_pose_round_trip(arm):
    rng = np.random.default_rng(1)
    targets = _targets(arm, 200, rng)
    failures = []
    for q, m in targets:
        seed = rng.uniform(arm.lower, arm.upper)
        try:
            sol = solve(arm, m.translation, _quat(m), seed, method="casadi")
        except NoIKSolution as exc:
            failures.append((q.tolist(), str(exc)))
            continue
        got = arm.fk(sol.q)
        assert sol.solver == "casadi" and sol.candidates == 0 and _within(arm, sol.q)
        assert np.linalg.norm(got.translation - m.translation) <= 1e-6
        assert _rot_err(got.rotation, m.rotation) <= 1e-6
        assert sol.position_error <= 1e-6 and sol.orientation_error <= 1e-6
    for f in failures:
        print("casadi full pose failed:", f)
    assert len(failures) <= 0.01 * len(targets), failures


@pytest.mark.slow
def test_position_only_round_trip(arm):
    rng = np.random.default_rng(2)
    targets = _targets(arm, 200, rng)
    failures = []
    for q, m in targets:
        seed = rng.uniform(arm.lower, arm.upper)
        try:
            sol = solve(arm, m.translation, None, seed, method="casadi")
        except NoIKSolution as exc:
            failures.append((q.tolist(), str(exc)))
            continue
        assert sol.solver == "casadi" and _within(arm, sol.q)
        assert np.linalg.norm(arm.fk(sol.q).translation - m.translation) <= 1e-6
        assert sol.position_error <= 1e-6 and sol.orientation_error == 0.0
    for f in failures:
        print("casadi position only failed:", f)
    assert len(failures) <= 0.01 * len(targets), failures


def test_seed_at_or_near_the_answer(arm):
    rng = np.random.default_rng(3)
    moved = []
    for q, m in _targets(arm, 40, rng):
        for quat in (_quat(m), None):
            sol = solve(arm, m.translation, quat, q, method="casadi")
            assert np.abs(sol.q - q).max() <= 1e-6
        # a seed a few degrees off: a full pose of a 6R arm has isolated solutions, the seed's is the one found
        near = np.clip(q + rng.normal(0.0, 0.02, q.shape), arm.lower, arm.upper)
        sol = solve(arm, m.translation, _quat(m), near, method="casadi")
        if np.abs(sol.q - q).max() > 1e-6:
            moved.append((q.tolist(), sol.q.tolist()))
    assert len(moved) <= 2, moved  # near the elbow singularity the two elbow solutions are close


def test_position_only_is_nearer_than_the_seed_allows(arm):
    """Position only, the 3 free dofs go to the seed: the answer is nearer the seed than the target's own q."""
    rng = np.random.default_rng(4)
    c = casadi_ik(arm)
    closer = 0
    targets = _targets(arm, 30, rng)
    for q, m in targets:
        seed = np.clip(q + rng.normal(0.0, 0.3, q.shape), arm.lower, arm.upper)
        sol = solve(arm, m.translation, None, seed, method="casadi")
        d_sol = float(np.sum(c.weights * (sol.q - seed) ** 2))
        d_q = float(np.sum(c.weights * (q - seed) ** 2))
        closer += d_sol <= d_q + 1e-12
    assert closer >= 0.9 * len(targets)


def test_refusals(arm):
    # out of reach: the chain's length bound, before IPOPT runs
    with pytest.raises(NoIKSolution, match="out of reach"):
        solve(arm, [1.0, 0.0, 0.3], [1.0, 0.0, 0.0, 0.0], method="casadi")
    with pytest.raises(NoIKSolution, match="out of reach"):
        solve(arm, [0.0, -0.5, 0.3], None, method="casadi")
    # a pose whose only solutions violate a limit (J5 at 126 deg > 115 deg): the closed form proves it, casadi agrees
    m = arm.fk(np.array([0.3, 0.3, 0.3, 0.0, 2.2, 0.0]))
    with pytest.raises(NoIKSolution, match="violate joint limits"):
        solve(arm, m.translation, _quat(m), method="closed_form")
    with pytest.raises(NoIKSolution, match=r"no solution within limits .*IPOPT.*best residual .* m, .* rad") as exc:
        solve(arm, m.translation, _quat(m), method="casadi")
    assert "J5 at its upper limit" in str(exc.value)
    # the base column and the input checks are the dispatcher's, shared with every method
    with pytest.raises(NoIKSolution, match="base column"):
        solve(arm, [0.0, 0.0, 0.05], None, method="casadi")
    with pytest.raises(ValueError, match="quaternion"):
        solve(arm, [0.2, 0.0, 0.2], [0.0, 0.0, 0.0, 0.0], method="casadi")
    with pytest.raises(ValueError, match="seed"):
        solve(arm, [0.2, 0.0, 0.2], None, [0.0] * 5, method="casadi")


def test_one_solver_per_robot_type(arm):
    assert casadi_ik(arm) is casadi_ik(ArmModel("meca500"))


# --------------------------------------------------------------------------- another arm, as data

_JOINT = """  <joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>
    <origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>
    <limit lower="{lo}" upper="{hi}" effort="10" velocity="2"/></joint>
"""


def _urdf(joints: list[tuple[str, str, str, str, float, float]], tool: str) -> str:
    """A serial chain: (kind, origin xyz, origin rpy, axis, lower, upper) per joint, then a fixed tool frame."""
    links = ["base"] + [f"l{i + 1}" for i in range(len(joints))]
    body = "".join(f'  <link name="{n}"/>\n' for n in [*links, "tool"])
    for i, (kind, xyz, rpy, axis, lo, hi) in enumerate(joints):
        body += _JOINT.format(
            name=f"j{i + 1}", kind=kind, parent=links[i], child=links[i + 1], xyz=xyz, rpy=rpy, axis=axis, lo=lo, hi=hi
        )
    body += (
        f'  <joint name="tool_joint" type="fixed"><parent link="{links[-1]}"/><child link="tool"/>'
        f'<origin xyz="{tool}" rpy="0.1 0.2 0.3"/></joint>\n'
    )
    return f'<?xml version="1.0"?>\n<robot name="t">\n{body}</robot>\n'


def _robot(tmp_path, monkeypatch, name: str, joints, tool: str = "0.1 0 0") -> ArmModel:
    d = tmp_path / name
    d.mkdir()
    (d / f"{name}.urdf").write_text(_urdf(joints, tool))
    (d / f"{name}.xml").write_text("<mujoco/>\n")  # the description requires the file; IK never reads it
    n = len(joints)
    (d / "robot.toml").write_text(
        f'[robot]\nname = "{name}"\nkind = "arm"\nurdf = "{name}.urdf"\nmjcf = "{name}.xml"\n'
        f'flange_frame = "tool"\njoints = {[f"j{i + 1}" for i in range(n)]}\n'.replace("'", '"')
        + f"lower = {[j[4] for j in joints]}\nupper = {[j[5] for j in joints]}\nmax_speed = {[2.0] * n}\n"
    )
    monkeypatch.setenv(ENV_PATH, str(tmp_path))
    return ArmModel(name)


@pytest.mark.slow
def test_a_three_joint_arm_from_a_urdf(tmp_path, monkeypatch):
    """Yaw, pitch, then an elbow about a tilted axis (revolute-unaligned in Pinocchio); position-only targets."""
    arm = _robot(
        tmp_path,
        monkeypatch,
        "tribot",
        [
            ("revolute", "0 0 0.1", "0 0 0", "0 0 1", -2.5, 2.5),
            ("revolute", "0 0 0.05", "0 0 0", "0 1 0", -1.5, 1.5),
            ("revolute", "0.3 0 0", "0 0 0", "0 0.6 0.8", -2.0, 2.0),
        ],
        tool="0.25 0 0.02",
    )
    assert arm.model.joints[3].shortname() == "JointModelRevoluteUnaligned"
    rng = np.random.default_rng(5)
    _fk_matches(arm, 200, rng)
    failures = []
    for _ in range(100):
        q = rng.uniform(arm.lower, arm.upper)
        p = arm.fk(q).translation
        try:
            sol = solve(arm, p, None, rng.uniform(arm.lower, arm.upper), method="casadi")
        except NoIKSolution as exc:
            failures.append((q.tolist(), str(exc)))
            continue
        assert sol.solver == "casadi" and _within(arm, sol.q)
        assert np.linalg.norm(arm.fk(sol.q).translation - p) <= 1e-6
    assert len(failures) <= 1, failures
    # the base joint cannot turn past 2.5 rad: a target straight behind it is out of its limits
    behind = arm.fk(np.array([math.pi, 0.3, 0.2])).translation
    with pytest.raises(NoIKSolution, match="no solution within limits"):
        solve(arm, behind, None, method="casadi")
    with pytest.raises(NoIKSolution, match="out of reach"):
        solve(arm, [2.0, 0.0, 0.0], None, method="casadi")


def test_prismatic_joints_and_unsupported_ones(tmp_path, monkeypatch):
    arm = _robot(
        tmp_path,
        monkeypatch,
        "slider",
        [
            ("prismatic", "0 0 0.1", "0 0 0", "0 0 1", 0.0, 0.4),
            ("revolute", "0 0 0.05", "0 0 0.3", "1 0 0", -1.5, 1.5),
            ("prismatic", "0.2 0 0", "0.2 0 0", "0.6 0 0.8", -0.1, 0.1),
        ],
    )
    rng = np.random.default_rng(6)
    _fk_matches(arm, 50, rng)
    q = rng.uniform(arm.lower, arm.upper)
    p = arm.fk(q).translation
    sol = solve(arm, p, None, q + 0.01 * (arm.upper - arm.lower), method="casadi")
    assert np.linalg.norm(arm.fk(sol.q).translation - p) <= 1e-6 and _within(arm, sol.q)
    spinner = _robot(
        tmp_path,
        monkeypatch,
        "spinner",
        [
            ("revolute", "0 0 0.1", "0 0 0", "0 0 1", -2.0, 2.0),
            ("continuous", "0.2 0 0", "0 0 0", "0 1 0", -3.0, 3.0),
        ],
    )
    with pytest.raises(ValueError, match="'j2' is a JointModelRUBY.*only 1-dof revolute and prismatic"):
        casadi_ik(spinner)
