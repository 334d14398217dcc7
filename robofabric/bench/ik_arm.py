"""``robofabric bench ik --robot NAME``: IK solve times and success on any installed arm (a type from
``robots add``: the UR5, the Panda), where :func:`compute_peer.kinematics.ik.solve` picks the numerical solver.

In this process, no network. Targets are FK of seeded random in-limit joint vectors (every one reachable, outside
the base column); a target counts as solved when ``solve`` returns joints within the limits whose FK is within
:data:`POSITION_TOL` and :data:`ROTATION_TOL` of it (``solve`` checks far tighter; this is the issue's bar). Three
workloads, each timed around ``solve`` alone:

- full pose, seed anywhere in the limits (a click on the 3D view);
- full pose, seed near the answer (+ N(0, 0.3 rad) per joint, like tracking a moving target);
- position only, seed anywhere (Test A's target sphere).
"""

from __future__ import annotations

import time

import numpy as np

from robofabric.bench.ik import _stats, reachable_targets

POSITION_TOL = 1e-3
"""m: a solution whose flange is farther from the target is counted as a failure."""
ROTATION_TOL = 1e-3
"""rad: the same for the orientation (full-pose workloads)."""

ROWS = (
    ("full_far", "full pose, seed anywhere"),
    ("full_near", "full pose, seed near (tracking)"),
    ("position", "position only, seed anywhere"),
)


def measure_arm(robot: str, n: int = 200, seed: int = 0) -> dict:
    """Success rate, median and p99 (us) of ``solve`` per workload on ``n`` reachable targets of ``robot``."""
    from compute_peer.kinematics.ik import solve
    from compute_peer.kinematics.ik_common import pose_errors, quaternion_to_matrix
    from compute_peer.kinematics.model import ArmModel, NoIKSolution

    if n < 1:
        raise ValueError("n must be >= 1")
    arm = ArmModel(robot)
    rng = np.random.default_rng(seed)
    targets = reachable_targets(arm, n, rng)
    anywhere = [rng.uniform(arm.lower, arm.upper) for _ in range(n)]
    near = [np.clip(q + rng.normal(0.0, 0.3, q.shape), arm.lower, arm.upper) for q, _, _ in targets]
    result: dict = {"robot": robot, "n": n, "seed": seed, "joints": int(arm.model.nq)}
    for key, seeds, full in (("full_far", anywhere, True), ("full_near", near, True), ("position", anywhere, False)):
        times, ok = [], 0
        for (_, p, quat), s in zip(targets, seeds):
            t0 = time.perf_counter()
            try:
                sol = solve(arm, p, quat if full else None, s)
            except NoIKSolution:
                continue
            times.append(time.perf_counter() - t0)
            rot = quaternion_to_matrix(*quat) if full else None
            pe, re = pose_errors(arm, sol.q, p, rot)
            inside = bool(np.all(sol.q >= arm.lower) and np.all(sol.q <= arm.upper))
            ok += pe <= POSITION_TOL and re <= ROTATION_TOL and inside
        result[key] = _stats(times, ok, n)
    return result


def format_table(result: dict) -> str:
    """The result as a markdown table (for docs/benchmarks.md)."""
    lines = [
        f"IK solve, {result['robot']} ({result['joints']} joints), {result['n']} reachable targets per row "
        f"(seed {result['seed']}), solved = within 1 mm and 1 mrad:",
        "",
        "| workload | success | p50 (us) | p99 (us) |",
        "|---|---|---|---|",
    ]
    for key, label in ROWS:
        r = result[key]
        lines.append(f"| {label} | {100 * r['success']:.1f}% | {r['median_us']:.0f} | {r['p99_us']:.0f} |")
    return "\n".join(lines)


__all__ = ["POSITION_TOL", "ROTATION_TOL", "ROWS", "format_table", "measure_arm"]
