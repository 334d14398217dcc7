"""Inverse kinematics: the entry point, which picks a solver per robot type and method.

:func:`solve` is the one entry point (the service layer calls it). It takes a
flange target in the arm's base frame, a position and optionally a quaternion
(w, x, y, z), and returns an :class:`IKSolution` inside the joint limits or
raises :class:`~compute_peer.kinematics.model.NoIKSolution` saying why; it never
returns a best effort. Malformed input (wrong shapes, NaN) raises plain
``ValueError``.

The solvers live one per module: the Meca500's closed form
(:mod:`.closed_form_ik`), Levenberg-Marquardt for any arm (:mod:`.numerical_ik`)
and CasADi/IPOPT (:mod:`.casadi_ik`); what they share is in :mod:`.ik_common`.
Their public names are importable from here as before.

Targets inside the base column (the description's ``base_radius``, up to J1)
are refused for every method: kinematics alone would fold the arm over its base.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .closed_form_ik import (
    CLOSED_FORMS,
    SHOULDER_SINGULAR,
    WRIST_SINGULAR,
    ClosedForm,
    meca500_ik,
)
from .ik_common import (
    LIMIT_SLACK,
    POSITION_CHECK,
    ROTATION_CHECK,
    TWO_PI,
    IKSolution,
    arm_constants,
    default_seed,
    joint_distance,
    nearest,
    pose_errors,
    quaternion_to_matrix,
)
from .model import ArmModel, NoIKSolution
from .numerical_ik import solve_numerical

__all__ = [
    "CLOSED_FORMS",
    "LIMIT_SLACK",
    "METHODS",
    "POSITION_CHECK",
    "ROTATION_CHECK",
    "SHOULDER_SINGULAR",
    "TILTS",
    "TWO_PI",
    "WRIST_SINGULAR",
    "ClosedForm",
    "IKSolution",
    "in_base_column",
    "joint_distance",
    "meca500_ik",
    "nearest",
    "quaternion_to_matrix",
    "solve",
    "solve_numerical",
]

METHODS = ("auto", "closed_form", "numerical", "casadi")


def _vector(name: str, value: object, n: int) -> list[float]:
    """``value`` as ``n`` finite floats, or ValueError. Plain lists: this runs on every solve."""
    if isinstance(value, (str, bytes)):
        raise ValueError(f"{name}: expected {n} numbers, got {value!r}")  # noqa: TRY004 (the contract: ValueError)
    if isinstance(value, np.ndarray):
        if value.shape != (n,):
            raise ValueError(f"{name}: expected shape ({n},), got {value.shape}")
        value = value.tolist()
    try:
        v = [float(x) for x in value]  # type: ignore[union-attr]
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected {n} numbers, got {value!r}") from None
    if len(v) != n:
        raise ValueError(f"{name}: expected {n} numbers, got {len(v)}")
    if not all(math.isfinite(x) for x in v):
        raise ValueError(f"{name}: not finite: {v}")
    return v


def _orientation_options(arm: ArmModel, p: list[float], seed: list[float]) -> list[tuple[str, list[list[float]]]]:
    """Flange orientations worth trying for a position-only target, in order of preference."""
    cur = arm.fk(np.asarray(seed)).rotation.tolist()
    phi = math.atan2(p[1], p[0]) if math.hypot(p[0], p[1]) > 1e-9 else seed[0]
    c, s = math.cos(phi), math.sin(phi)
    # columns: flange x, y, z. Down: z = -base z, x radially outward. Horizontal: z outward, x down.
    down = [[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]]
    horizontal = [[0.0, -s, c], [0.0, c, s], [-1.0, 0.0, 0.0]]
    options = [("seed", cur), ("down", down), ("horizontal", horizontal)]
    # then the tool tilted in and around the radial plane: cheap closed-form tries before the numerical solver
    for elevation, azimuth in TILTS:
        options.append(
            (
                f"tilted {elevation:+.0f}/{azimuth:+.0f} deg",
                tool_frame(phi + math.radians(azimuth), math.radians(elevation)),
            )
        )
    return options


TILTS = ((-45.0, 0.0), (45.0, 0.0), (-60.0, 45.0), (-60.0, -45.0), (0.0, 60.0), (0.0, -60.0), (70.0, 0.0), (-20.0, 0.0))
"""(elevation, azimuth from radial) of the extra tool directions tried for position-only targets, in degrees."""


def tool_frame(azimuth: float, elevation: float) -> list[list[float]]:
    """A flange rotation whose z (the tool) points at ``azimuth`` / ``elevation``; x in the vertical plane."""
    ca, sa, ce, se = math.cos(azimuth), math.sin(azimuth), math.cos(elevation), math.sin(elevation)
    z = (ce * ca, ce * sa, se)
    x = (se * ca, se * sa, -ce)  # perpendicular to z, pointing down-ish like Mecademic's convention
    y = (z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0])
    return [[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]]


def _keep_roll(
    arm: ArmModel, q: tuple[float, ...], joint: int | None, seed: list[float], p: list[float]
) -> tuple[tuple[float, ...], float] | None:
    """``q`` with the roll joint at the seed's angle, and its position error (FK); None if FK disagrees."""
    if joint is not None:
        v = min(arm.upper[joint], max(arm.lower[joint], seed[joint]))
        q = q[:joint] + (float(v),) + q[joint + 1 :]
    pe, _ = pose_errors(arm, q, p, None)
    return (q, pe) if pe <= POSITION_CHECK else None


def _base_column(arm: ArmModel) -> tuple[float, float]:
    """(radius, top height) of the base column: ``base_radius`` up to J1's frame; radius 0 when none."""
    return arm.description.base_radius, float(arm.model.jointPlacements[1].translation[2])


def in_base_column(arm: ArmModel, position: Sequence[float]) -> bool:
    """Whether a flange position lies inside the base column, which :func:`solve` refuses."""
    radius, top = _base_column(arm)
    return math.hypot(position[0], position[1]) < radius and position[2] < top


def _refuse_base_column(arm: ArmModel, p: list[float]) -> None:
    """A flange target inside the base column (``base_radius``, up to J1's frame) is refused up front.

    Kinematics alone would fold the arm over its own base to get there (the
    Meca500 reaches (0, 0, 0.05) with J2 at 90 deg); this is not collision
    checking, only the one keep-out every target request can be tested against.
    """
    if in_base_column(arm, p):
        radius, top = _base_column(arm)
        raise NoIKSolution(
            f"inside the base column: {math.hypot(p[0], p[1]):.3f} m from its axis < radius "
            f"{radius:.3f} m, {p[2]:.3f} m high < top {top:.3f} m"
        )


_REVOLUTE_JOINTS = (
    "JointModelRX",
    "JointModelRY",
    "JointModelRZ",
    "JointModelRevoluteUnaligned",
    "JointModelRUBX",
    "JointModelRUBY",
    "JointModelRUBZ",
    "JointModelRevoluteUnboundedUnaligned",
)


def longest_reach(arm: ArmModel) -> float:
    """A bound on how far from the base's origin the flange can ever be: the lengths of the links from the base
    to the flange, added (a revolute joint's motion keeps each link's length); infinite when a joint of the chain
    is not revolute (a prismatic one lengthens it)."""
    model = arm.model
    frame = model.frames[arm.frame_id]
    total, j = float(np.linalg.norm(frame.placement.translation)), frame.parentJoint
    while j > 0:
        if model.joints[j].shortname() not in _REVOLUTE_JOINTS:
            return math.inf
        total += float(np.linalg.norm(model.jointPlacements[j].translation))
        j = model.parents[j]
    return total


def _refuse_out_of_reach(arm: ArmModel, p: list[float]) -> None:
    """A target beyond every link's length added is refused before the numerical solver runs (it tried 25 starts
    at a target 1e9 m away)."""
    dist, reach = math.hypot(*p), longest_reach(arm)
    if dist > reach * (1 + 1e-9):
        raise NoIKSolution(
            f"out of reach: the target is {dist:.4g} m from the arm's base, beyond its longest reach of {reach:.4f} m"
        )


def solve(
    arm: ArmModel,
    position: Sequence[float],
    quaternion: Sequence[float] | None = None,
    seed: Sequence[float] | None = None,
    *,
    method: str = "auto",
) -> IKSolution:
    """Joint angles putting ``arm``'s flange at ``position`` (and ``quaternion``, w x y z), base frame.

    ``method``: "auto" (the robot type's closed form if it has one, else
    numerical), "closed_form", "numerical" or "casadi" (IPOPT, hard joint limits:
    :mod:`~compute_peer.kinematics.casadi_ik`). The result is the solution nearest
    ``seed`` (default: the zero pose) in weighted joint distance. Without a
    quaternion the orientation is free: the closed form tries the seed's flange
    orientation, then the tool pointing down, then horizontal and radially
    outward, then falls back to numerical position-only IK from the seed; the
    closed form keeps the roll joint (J6) at the seed's angle, as it cannot move
    the flange. Raises :class:`NoIKSolution` (with the reason) when nothing inside the limits
    reaches the target, ``ValueError`` for malformed input.
    """
    if method not in METHODS:
        raise ValueError(f"method {method!r}: expected one of {', '.join(METHODS)}")
    nq = arm.model.nq
    p = _vector("position", position, 3)
    rot: tuple[tuple[float, ...], ...] | None = None
    if quaternion is not None:
        qv = _vector("quaternion", quaternion, 4)
        n = math.sqrt(sum(x * x for x in qv))
        if n <= 1e-6:
            raise ValueError(f"quaternion: norm {n:.3g} is too small to normalize")
        rot = quaternion_to_matrix(*(x / n for x in qv))
    if seed is None:
        s = default_seed(arm)
    else:  # a seed is a hint (often a measured state a hair past a limit): clamp it, don't refuse it
        s = [min(hi, max(lo, v)) for v, (lo, hi, _) in zip(_vector("seed", seed, nq), arm_constants(arm).limits)]
    _refuse_base_column(arm, p)
    closed = CLOSED_FORMS.get(arm.description.name)
    if method == "closed_form" and closed is None:
        raise ValueError(f"robot type {arm.description.name!r} has no closed-form IK")
    if method == "casadi":
        from .casadi_ik import solve_casadi  # imports CasADi on first use only

        q, pe, re = solve_casadi(arm, p, rot, s)
        return _solution(q, "casadi", pe, re, 0)
    if method == "numerical" or closed is None:
        _refuse_out_of_reach(arm, p)  # the closed form and CasADi check their own (tighter) reach first
        q, pe, re = solve_numerical(arm, p, rot, s)
        return _solution(q, "numerical", pe, re, 0)
    if rot is not None:
        cands, reason = closed.candidates(arm, p, rot, s)
        if not cands:
            raise NoIKSolution(reason)
        best = cands[nearest(arm, [c.q for c in cands], s)]
        return _solution(best.q, "closed_form", best.position_error, best.orientation_error, len(cands))
    return _solve_position_closed(arm, closed, p, s)


def _solve_position_closed(arm: ArmModel, closed: ClosedForm, p: list[float], s: list[float]) -> IKSolution:
    dist = math.dist(p, closed.shoulder)
    if dist > closed.reach:
        raise NoIKSolution(f"out of reach: distance to shoulder {dist:.4g} m > max {closed.reach:.4f} m")
    reasons = []
    for name, rot in _orientation_options(arm, p, s):
        cands, reason = closed.candidates(arm, p, rot, s)
        # twins that differed only in the roll joint become one
        kept = {k[0]: k[1] for k in (_keep_roll(arm, c.q, closed.roll_joint, s, p) for c in cands) if k is not None}
        if kept:
            qs = list(kept)
            q = qs[nearest(arm, qs, s)]
            return _solution(q, "closed_form", kept[q], 0.0, len(qs))
        reasons.append(f"tool {name}: {reason or 'the FK check failed'}")
    try:
        q, pe, _ = solve_numerical(arm, p, None, s)
    except NoIKSolution as exc:
        raise NoIKSolution(f"{exc}; closed form: " + "; ".join(reasons)) from None
    return _solution(q, "numerical", pe, 0.0, 0)


def _solution(q: Sequence[float], solver: str, pe: float, re: float, n: int) -> IKSolution:
    arr = np.array(q, dtype=float)
    arr.flags.writeable = False
    return IKSolution(arr, solver, float(pe), float(re), n)
