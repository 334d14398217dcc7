"""What the IK solvers share: the solution type, FK checks, joint distance and angle helpers.

Each solver (:mod:`.closed_form_ik`, :mod:`.numerical_ik`, :mod:`.casadi_ik`)
lives in its own module; :mod:`.ik` is the entry point that picks one.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from fabric.interfaces.geometry import TWO_PI

from .model import ArmModel

POSITION_CHECK = 1e-9
"""m: a closed-form solution whose FK misses the target by more is a bug, and is dropped."""
ROTATION_CHECK = 1e-8
"""rad: the same for orientation."""
LIMIT_SLACK = 1e-9
"""rad: a joint this close outside a limit is rounding, and is clamped onto it."""


@dataclass(frozen=True, slots=True)
class IKSolution:
    """One joint vector reaching the target, how it was found and how well FK agrees."""

    q: np.ndarray  # joint angles (rad), within limits; read-only
    solver: str  # "closed_form" | "numerical" | "casadi"
    position_error: float  # m, from FK of q
    orientation_error: float  # rad (0.0 for position-only targets)
    candidates: int  # in-limit solutions the closed form found (0 for numerical)


def quaternion_to_matrix(w: float, x: float, y: float, z: float) -> tuple[tuple[float, ...], ...]:
    """Rotation matrix (row tuples) of a unit quaternion (w, x, y, z)."""
    return (
        (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)),
    )


@dataclass(frozen=True, slots=True)
class ArmConstants:
    """Per-arm lists read once: plain floats, because the closed form's budget is ~100 us."""

    limits: tuple[tuple[float, float, bool], ...]  # lower, upper, spans a full turn (2 pi twins possible)
    weights: tuple[float, ...]


_CONSTANTS: weakref.WeakKeyDictionary[ArmModel, ArmConstants] = weakref.WeakKeyDictionary()


def arm_constants(arm: ArmModel) -> ArmConstants:
    c = _CONSTANTS.get(arm)
    if c is None:
        lo, hi = arm.lower.tolist(), arm.upper.tolist()
        limits = tuple((a, b, b - a >= TWO_PI - 2 * LIMIT_SLACK) for a, b in zip(lo, hi))
        c = _CONSTANTS[arm] = ArmConstants(limits, tuple(_weights(arm)))
    return c


def _weights(arm: ArmModel) -> list[float]:
    """Per-joint weights of the seed distance: 1 / max speed, so the distance is roughly a move time.

    A degree of J1 (150 deg/s) costs more than a degree of J6 (500 deg/s), so the
    nearest solution is the quickest to reach, not the one with the least total angle.
    """
    speeds = arm.description.max_speed
    if len(speeds) == arm.model.nq and all(s > 0 for s in speeds):
        return [1.0 / s for s in speeds]
    return [1.0] * arm.model.nq


def joint_distance(arm: ArmModel, q: Sequence[float], seed: Sequence[float]) -> float:
    """Weighted squared joint distance (s^2 at full speed); no 2 pi wrapping: joints with limits travel."""
    return sum((w * (a - b)) ** 2 for w, a, b in zip(arm_constants(arm).weights, q, seed))


def pose_errors(
    arm: ArmModel, q: Sequence[float], p: Sequence[float], rot: Sequence[Sequence[float]] | None
) -> tuple[float, float]:
    """FK of ``q`` through the arm's Pinocchio model (what :meth:`ArmModel.fk` does, minus the copy)."""
    pin.framesForwardKinematics(arm.model, arm.data, np.array(q, dtype=float))
    m = arm.data.oMf[arm.frame_id]
    t = m.translation.tolist()
    pe = math.sqrt((t[0] - p[0]) ** 2 + (t[1] - p[1]) ** 2 + (t[2] - p[2]) ** 2)
    if rot is None:
        return pe, 0.0
    (a0, a1, a2), (b0, b1, b2), (c0, c1, c2) = m.rotation.tolist()
    (x0, x1, x2), (y0, y1, y2), (z0, z1, z2) = rot
    s = (
        (a0 - x0) ** 2
        + (a1 - x1) ** 2
        + (a2 - x2) ** 2
        + (b0 - y0) ** 2
        + (b1 - y1) ** 2
        + (b2 - y2) ** 2
        + (c0 - z0) ** 2
        + (c1 - z1) ** 2
        + (c2 - z2) ** 2
    )
    return pe, angle_from_frobenius(math.sqrt(s))


def angle_from_frobenius(d: float) -> float:
    """Angle (rad) between two rotations whose matrices differ by ``d = |A - B|_F = 2 sqrt(2) sin(angle / 2)``.

    Exact near zero, where ``acos((trace - 1) / 2)`` cannot resolve angles below ~1e-8 rad: the solvers'
    FK checks are tighter than that.
    """
    return 2.0 * math.asin(min(1.0, d / (2.0 * math.sqrt(2.0))))


def rotation_error(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (rad) between two rotation matrices (see :func:`angle_from_frobenius`)."""
    return angle_from_frobenius(float(np.linalg.norm(np.asarray(a) - np.asarray(b))))


def degrees_text(a: float) -> str:
    """An angle (rad) as degrees for a refusal's reason, e.g. ``"12.3°"``."""
    return f"{math.degrees(a):.1f}\N{DEGREE SIGN}"


def nearest(arm: ArmModel, solutions: Sequence[Sequence[float]], seed: Sequence[float]) -> int:
    """Index of the solution nearest ``seed`` in weighted joint distance."""
    if not solutions:
        raise ValueError("no solutions to choose from")
    w = arm_constants(arm).weights
    ws = [wi * b for wi, b in zip(w, seed)]
    d = [math.dist([wi * a for wi, a in zip(w, q)], ws) for q in solutions]
    return d.index(min(d))


def default_seed(arm: ArmModel) -> list[float]:
    """The zero pose clamped into the limits: what a seedless request is nearest to."""
    return np.clip(np.zeros(arm.model.nq), arm.lower, arm.upper).tolist()
