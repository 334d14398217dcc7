"""``robofabric bench ik``: how long :func:`compute_peer.kinematics.ik.solve` takes on the Meca500.

In this process, no network. Targets are FK of seeded random in-limit joint
vectors (so every one is reachable), skipping those whose flange lands inside
the base column, which ``solve`` refuses by design. Three workloads, each timed
around ``solve`` alone (input checks, solving, the FK check, choosing):

- closed form, full pose: seed an unrelated random joint vector;
- closed form, position only: the same; falls back to numerical when the
  three preferred orientations all fail (counted in ``numerical_fallback``);
- numerical (Levenberg-Marquardt), full pose: half the seeds near the answer
  (+ N(0, 0.3 rad) per joint, like tracking a moving target), half anywhere;
- CasADi + IPOPT, full pose: the first ``min(n, CASADI_TARGETS)`` targets with
  the closed form's seeds (it takes milliseconds a solve).

A refusal counts against the success rate, not the times.
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING, Annotated

import numpy as np
import typer

from robofabric.bench.common import TablesOut, append

if TYPE_CHECKING:
    from compute_peer.kinematics.model import ArmModel

ROBOT = "meca500"
CASADI_TARGETS = 300
"""The CasADi row solves at most this many of the targets (~10 ms each)."""


def _stats(times: list[float], ok: int, n: int) -> dict:
    us = [t * 1e6 for t in times]
    return {
        "n": n,
        "success": ok / n if n else math.nan,
        "median_us": float(np.median(us)) if us else math.nan,
        "p99_us": float(np.percentile(us, 99)) if us else math.nan,
    }


def reachable_targets(
    arm: ArmModel, n: int, rng: np.random.Generator
) -> list[tuple[np.ndarray, np.ndarray, list[float]]]:
    """``n`` reachable flange targets: (joint vector, position, quaternion w x y z)."""
    import pinocchio as pin

    from compute_peer.kinematics.ik import in_base_column

    out = []
    while len(out) < n:
        q = rng.uniform(arm.lower, arm.upper)
        m = arm.fk(q)
        p = m.translation.copy()
        if in_base_column(arm, p):
            continue
        quat = pin.Quaternion(m.rotation)
        out.append((q, p, [quat.w, quat.x, quat.y, quat.z]))
    return out


def _timed(arm: ArmModel, jobs: list, method: str = "auto") -> tuple[list[float], list]:
    """Solve time (s) and solution of every (position, quaternion or None, seed) job that succeeds."""
    from compute_peer.kinematics.ik import solve
    from compute_peer.kinematics.model import NoIKSolution

    times, sols = [], []
    for p, quat, s in jobs:
        t0 = time.perf_counter()
        try:
            sol = solve(arm, p, quat, s, method=method)
        except NoIKSolution:
            continue
        times.append(time.perf_counter() - t0)
        sols.append(sol)
    return times, sols


def measure_solve(n: int = 2000, seed: int = 0) -> dict:
    """Median and p99 (us) and success rates of ``solve`` per workload: ``n`` targets each, CasADi fewer."""
    from compute_peer.kinematics.model import ArmModel

    if n < 1:
        raise ValueError("n must be >= 1")
    arm = ArmModel(ROBOT)
    rng = np.random.default_rng(seed)
    targets = reachable_targets(arm, n, rng)
    seeds = [rng.uniform(arm.lower, arm.upper) for _ in range(n)]
    result: dict = {"robot": ROBOT, "n": n, "seed": seed}

    times, sols = _timed(arm, [(p, quat, s) for (_, p, quat), s in zip(targets, seeds)])
    result["closed_form"] = _stats(times, len(sols), n)

    times, sols = _timed(arm, [(p, None, s) for (_, p, _), s in zip(targets, seeds)])
    fallback = sum(sol.solver == "numerical" for sol in sols)
    result["closed_form_position"] = _stats(times, len(sols), n) | {"numerical_fallback": fallback}

    # half the starts near the answer (a tracking seed), half anywhere in the limits
    starts = [
        np.clip(q + rng.normal(0.0, 0.3, q.shape), arm.lower, arm.upper) if i % 2 == 0 else s
        for i, ((q, _, _), s) in enumerate(zip(targets, seeds))
    ]
    times, sols = _timed(arm, [(p, quat, st) for (_, p, quat), st in zip(targets, starts)], "numerical")
    result["numerical"] = _stats(times, len(sols), n)

    m = min(n, CASADI_TARGETS)
    times, sols = _timed(arm, [(p, quat, s) for (_, p, quat), s in zip(targets[:m], seeds[:m])], "casadi")
    result["casadi"] = _stats(times, len(sols), m)
    return result


ROWS = (
    ("closed_form", "closed form, full pose"),
    ("closed_form_position", "closed form, position only"),
    ("numerical", "numerical (LM), full pose"),
    ("casadi", "CasADi + IPOPT, full pose"),
)


def format_table(result: dict) -> str:
    """The result as a markdown table (for docs/benchmarks/kinematics.md)."""
    lines = [
        "| solver | targets | success | median (us) | p99 (us) |",
        "|---|---|---|---|---|",
    ]
    for key, label in ROWS:
        r = result[key]
        extra = f" ({r['numerical_fallback']} via numerical)" if "numerical_fallback" in r else ""
        lines.append(
            f"| {label} | {r['n']} | {100 * r['success']:.2f}%{extra} | {r['median_us']:.1f} | {r['p99_us']:.1f} |"
        )
    return "\n".join(lines)


def command(
    n: Annotated[int, typer.Option("--n", help="Random reachable targets per workload.")] = 2000,
    seed: Annotated[int, typer.Option(help="Seed of the targets and IK seeds.")] = 0,
    queries: Annotated[
        int, typer.Option(help="IK/FK queries for the round trip through a router (0: skip it).")
    ] = 1000,
    robot: Annotated[
        str,
        typer.Option(
            "--robot",
            help="An installed arm type other than the Meca500 (robofabric robots list): its numerical IK, no round trip.",
        ),
    ] = ROBOT,
    out: TablesOut = None,
) -> None:
    """Meca500 IK solve times (closed form full pose / position only, numerical, CasADi) and the query round trip;
    with --robot, any installed arm's IK: success within 1 mm and 1 mrad, p50 and p99.

    The round trip runs a `robofabric compute` process behind a router hosted here, as on a LAN.
    """
    from rich.console import Console
    from rich.table import Table

    from fabric.cli_common import UserError

    if n < 1:
        raise UserError("--n must be >= 1")
    if robot != ROBOT:
        from robofabric.bench.ik_arm import format_table as arm_table, measure_arm

        try:
            text = arm_table(measure_arm(robot, n, seed))
        except ValueError as exc:  # an unknown type, or one the compute peer cannot model
            raise UserError(str(exc)) from None
        print(text)
        append(out, text + "\n")
        return
    result = measure_solve(n, seed)
    table = Table(title=f"IK solve, {ROBOT}, {n} targets per row, CasADi {min(n, CASADI_TARGETS)} (seed {seed})")
    for col in ("solver", "success", "median (us)", "p99 (us)"):
        table.add_column(col, justify="left" if col == "solver" else "right")
    for key, label in ROWS:
        r = result[key]
        extra = f" ({r['numerical_fallback']} numerical)" if "numerical_fallback" in r else ""
        table.add_row(label, f"{100 * r['success']:.2f}%{extra}", f"{r['median_us']:.1f}", f"{r['p99_us']:.1f}")
    Console().print(table)
    md = [
        f"IK solve, {ROBOT}, {n} targets per row, CasADi {min(n, CASADI_TARGETS)} (seed {seed}):",
        "",
        format_table(result),
    ]
    if queries > 0:
        from robofabric.bench.ik_query import measure_query

        rt = measure_query(queries, seed)
        qt = Table(title=f"query round trip through a router, compute peer in its own process ({queries} each)")
        for col in ("query", "p50 (ms)", "p99 (ms)", "max (ms)"):
            qt.add_column(col, justify="left" if col == "query" else "right")
        md += ["", "| query | p50 (ms) | p99 (ms) | max (ms) |", "|---|---|---|---|"]
        for name, r in rt.items():
            qt.add_row(name, f"{r['p50_ms']:.3f}", f"{r['p99_ms']:.3f}", f"{r['max_ms']:.3f}")
            md.append(f"| {name} | {r['p50_ms']:.3f} | {r['p99_ms']:.3f} | {r['max_ms']:.3f} |")
        Console().print(qt)
    append(out, "\n".join(md) + "\n")
