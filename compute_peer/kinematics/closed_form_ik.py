"""Closed-form IK: the Meca500's, and the registry of robot types that have one.

The Meca500 has a spherical wrist, so its IK splits into a position problem for
the wrist centre (J1-J3) and an orientation problem for the wrist (J4-J6), each
with two branches: up to 8 solutions, plus 2 pi twins of joints whose range
allows them (J6 spans +-180 deg). Every dimension comes from
:mod:`robots.meca500.geometry`, and every returned solution is checked by forward
kinematics through Pinocchio, which catches a derivation slip instead of
returning a wrong pose.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from fabric.interfaces.geometry import wrap_angle
from robots.meca500 import geometry as _geo

from .ik_common import (
    LIMIT_SLACK,
    POSITION_CHECK,
    ROTATION_CHECK,
    TWO_PI,
    arm_constants,
    default_seed,
    degrees_text,
    joint_distance,
    pose_errors,
    quaternion_to_matrix,
)
from .model import ArmModel, NoIKSolution

WRIST_SINGULAR = 1e-9
"""sin(q5) below this: J4 and J6 are one rotation; J4 keeps the seed's value."""
SHOULDER_SINGULAR = 1e-10
"""m: a wrist centre this close to the J1 axis leaves q1 free; it keeps the seed's value."""


@dataclass(frozen=True, slots=True)
class _Meca500Geometry:
    """The dimensions the closed form needs, read from robots.meca500.geometry (and checked to fit)."""

    shoulder_z: float  # J2 axis height above the base frame
    upper_arm: float  # J2 -> J3
    forearm_x: float  # J3 -> wrist centre, along the forearm (the J4 axis)
    forearm_z: float  # J3 -> J4 axis, perpendicular to the forearm
    wrist_to_flange: float  # wrist centre -> flange, along the J6 axis
    flange: tuple[tuple[float, ...], ...]  # flange rotation in link 6
    reach_min: float  # |J2 -> wrist centre| bounds
    reach_max: float
    elbow_phi: float  # angle of the J3 -> wrist vector from link 3's z axis, at q3 = 0

    @classmethod
    def from_module(cls) -> _Meca500Geometry:
        j = _geo.JOINTS
        axes = tuple(jt.axis for jt in j)
        if axes != (_geo.Z, _geo.Y, _geo.Y, _geo.X, _geo.Y, _geo.X) or len(j) != 6:
            raise RuntimeError(f"meca500 geometry changed: joint axes {axes} do not fit the closed form")
        # the derivation assumes these offsets are zero (a planar arm on the J1 axis, a spherical wrist)
        zero = (j[0].origin[:2], j[1].origin[:2], j[2].origin[:2], j[3].origin[:2], j[4].origin[1:], j[5].origin[1:])
        if any(v != 0.0 for pair in zero for v in pair):
            raise RuntimeError("meca500 geometry changed: an offset the closed form assumes zero is not")
        fx, fz = j[4].origin[0], j[3].origin[2]
        d = math.hypot(fx, fz)
        l2 = j[2].origin[2]
        return cls(
            shoulder_z=j[0].origin[2] + j[1].origin[2],
            upper_arm=l2,
            forearm_x=fx,
            forearm_z=fz,
            wrist_to_flange=j[5].origin[0],
            flange=quaternion_to_matrix(*_geo.FLANGE_QUAT),
            reach_min=abs(l2 - d),
            reach_max=l2 + d,
            elbow_phi=math.atan2(fx, fz),
        )


_MECA = _Meca500Geometry.from_module()


@dataclass(frozen=True, slots=True)
class _Candidate:
    q: tuple[float, ...]
    position_error: float
    orientation_error: float


def _fit(v: float, lim: tuple[float, float, bool]) -> float | None:
    """``v`` (wrapped into (-pi, pi]) or its 2 pi twin inside [lo, hi], clamped onto the limits; else None."""
    lo, hi = lim[0], lim[1]
    if v < lo - LIMIT_SLACK:
        v += TWO_PI
    elif v > hi + LIMIT_SLACK:
        v -= TWO_PI
    if lo - LIMIT_SLACK <= v <= hi + LIMIT_SLACK:
        return min(hi, max(lo, v))
    return None


Limits = tuple[tuple[float, float, bool], ...]
"""Per joint (lower, upper, wide): wide when its range holds a 2 pi twin of some angles."""


def _meca500_branches(
    p: Sequence[float], rot: Sequence[Sequence[float]], seed: Sequence[float], lims: Limits
) -> tuple[list[list[float]], list[tuple[int, float]], int, str]:
    """The in-limit joint vectors among the (up to 8) branches for the flange pose.

    Returns (inside, bad, branches, reason): ``bad`` holds, per rejected branch,
    its first joint outside the limits; ``reason`` is set when no branch exists
    (out of reach). A branch whose q1..q3 already fail skips the wrist.

    Derivation (link frames are parallel to the base frame at the zero pose):
    R6 = R Rf^T is link 6's rotation; the wrist centre is c = p - w R6 x.
    In J1's plane (u radial, h above J2), the wrist centre is
    Ry(q2) [(0, 0, L2) + Ry(q3) (a, 0, b)], so |c|^2 = L2^2 + d^2 + 2 L2 (b c3 - a s3)
    gives q3 (elbow up/down) and the direction of c gives q2. Then
    Rx(q4) Ry(q5) Rx(q6) = (Rz(q1) Ry(q2 + q3))^T R6, an X-Y-X Euler triple
    with two branches (wrist flip).

    The steps are plain-float functions (numpy is ~10x slower at this size); the limit checks inline the
    common case, ``v if lo <= v <= hi else _fit(v, lim)``, which saves ~25 calls a solve.
    """
    r6 = _link6_rotation(rot)
    cx, cy, h, dist = _wrist_centre(p, r6)
    reason = _reach_reason(dist)
    if reason:
        return [], [], 0, reason
    q1a, u = _shoulder(cx, cy, seed[0])
    elbows = _elbows(dist)
    inside: list[list[float]] = []
    bad: list[tuple[int, float]] = []
    n = 0
    l1 = lims[0]
    wide = [i for i, lim in enumerate(lims) if lim[2]]
    for q1raw, uu in ((q1a, u), (wrap_angle(q1a + math.pi, include_pi=True), -u)):
        q1 = q1raw if l1[0] <= q1raw <= l1[1] else _fit(q1raw, l1)
        if q1 is None:
            n += 2 * len(elbows)
            bad.append((0, q1raw))
            continue
        after_j1 = _after_j1(r6, q1)
        for q3r in elbows:
            n += 2
            upper = _upper_arm(q3r, h, uu, lims, bad)
            if upper is None:
                continue
            q2, q3 = upper
            wrists = _wrists(after_j1, q2 + q3, seed[3])
            n -= 2 - len(wrists)  # at the wrist singularity J4 and J6 merge: one wrist branch, not two
            for wrist in _wrists_in_limits(wrists, lims, bad):
                q = [q1, q2, q3, *wrist]
                inside.append(q)
                if wide:
                    inside.extend(_twins(q, lims, wide))
    return inside, bad, n, ""


def _link6_rotation(rot: Sequence[Sequence[float]]) -> list[tuple[float, float, float]]:
    """R6 = R Rf^T (row i, column j = sum_k R[i][k] Rf[j][k]), unrolled."""
    (f00, f01, f02), (f10, f11, f12), (f20, f21, f22) = _MECA.flange
    return [
        (a0 * f00 + a1 * f01 + a2 * f02, a0 * f10 + a1 * f11 + a2 * f12, a0 * f20 + a1 * f21 + a2 * f22)
        for a0, a1, a2 in rot
    ]


def _wrist_centre(p: Sequence[float], r6: list[tuple[float, float, float]]) -> tuple[float, float, float, float]:
    """The wrist centre c = p - w R6 x: (cx, cy, its height above J2, its distance from J2)."""
    g = _MECA
    w = g.wrist_to_flange
    cx, cy, cz = p[0] - w * r6[0][0], p[1] - w * r6[1][0], p[2] - w * r6[2][0]
    h = cz - g.shoulder_z
    return cx, cy, h, math.hypot(math.hypot(cx, cy), h)


def _reach_reason(dist: float) -> str:
    """Why no branch reaches a wrist centre ``dist`` from the shoulder, or '' when some does."""
    g = _MECA
    if dist > g.reach_max * (1 + 1e-12):
        return f"out of reach: wrist centre {dist:.4f} m from the shoulder > max {g.reach_max:.4f} m"
    if dist < g.reach_min * (1 - 1e-12):
        return f"too close: wrist centre {dist:.4f} m from the shoulder < min {g.reach_min:.4f} m"
    return ""


def _shoulder(cx: float, cy: float, seed_q1: float) -> tuple[float, float]:
    """(q1, u): J1 facing the wrist centre and the centre's radial distance in J1's plane; on the J1 axis,
    where q1 is free, the seed's q1."""
    r = math.hypot(cx, cy)
    if r < SHOULDER_SINGULAR:
        return seed_q1, cx * math.cos(seed_q1) + cy * math.sin(seed_q1)
    return math.atan2(cy, cx), r


def _elbows(dist: float) -> tuple[float, ...]:
    """q3 of elbow up and elbow down (one at full stretch): b c3 - a s3 = d cos(q3 + phi) = k."""
    g = _MECA
    l2, d = g.upper_arm, math.hypot(g.forearm_x, g.forearm_z)
    k = (dist * dist - l2 * l2 - d * d) / (2.0 * l2)
    t = math.acos(max(-1.0, min(1.0, k / d)))
    return (t - g.elbow_phi,) if t < 1e-12 else (t - g.elbow_phi, -t - g.elbow_phi)


def _after_j1(r6: list[tuple[float, float, float]], q1: float) -> tuple[tuple[float, ...], ...]:
    """Link 6's rotation seen after J1, Rz(-q1) R6, by rows."""
    c1, s1 = math.cos(q1), math.sin(q1)
    (x0, x1, x2), (y0, y1, y2) = r6[0], r6[1]
    return (
        (c1 * x0 + s1 * y0, c1 * x1 + s1 * y1, c1 * x2 + s1 * y2),
        (c1 * y0 - s1 * x0, c1 * y1 - s1 * x1, c1 * y2 - s1 * x2),
        r6[2],
    )


def _upper_arm(
    q3r: float, h: float, u: float, lims: Limits, bad: list[tuple[int, float]]
) -> tuple[float, float] | None:
    """(q2, q3) in limits for the elbow ``q3r`` and the wrist centre at (u, h) in J1's plane; None, and the
    first joint outside its limits added to ``bad``, otherwise."""
    g = _MECA
    l2, a, b = g.upper_arm, g.forearm_x, g.forearm_z
    l2lim, l3 = lims[1], lims[2]
    q3w = wrap_angle(q3r, include_pi=True)
    c3, s3 = math.cos(q3w), math.sin(q3w)
    vx, vz = a * c3 + b * s3, l2 - a * s3 + b * c3
    q2w = wrap_angle(math.atan2(vz, vx) - math.atan2(h, u), include_pi=True)
    q2 = q2w if l2lim[0] <= q2w <= l2lim[1] else _fit(q2w, l2lim)
    if q2 is None:
        bad.append((1, q2w))
        return None
    q3 = q3w if l3[0] <= q3w <= l3[1] else _fit(q3w, l3)
    if q3 is None:
        bad.append((2, q3w))
        return None
    return q2, q3


def _wrists(
    after_j1: tuple[tuple[float, ...], ...], th: float, seed_q4: float
) -> tuple[tuple[float, float, float], ...]:
    """(q4, q5, q6) of both wrist branches (flip), from the X-Y-X angles of M = Ry(q2 + q3)^T Rz(-q1) R6;
    one branch at the wrist singularity, where J4 keeps the seed's angle."""
    m10, m11, m12 = after_j1
    ct, st = math.cos(th), math.sin(th)
    # only the entries of M the X-Y-X angles need
    m00 = ct * m10[0] - st * m12[0]
    m01 = ct * m10[1] - st * m12[1]
    m02 = ct * m10[2] - st * m12[2]
    s5 = math.hypot(m01, m02)
    if s5 < WRIST_SINGULAR:
        m11_, m21 = m11[1], st * m10[1] + ct * m12[1]
        q4 = seed_q4
        if m00 > 0:  # q5 = 0: Rx(q4 + q6)
            return ((q4, math.atan2(s5, m00), wrap_angle(math.atan2(m21, m11_) - q4, include_pi=True)),)
        # q5 = pi (outside the Meca500's J5 range; kept for completeness): Rx(q4 - q6)
        return ((q4, math.pi, wrap_angle(q4 - math.atan2(m21, m11_), include_pi=True)),)
    m10_, m20 = m11[0], st * m10[0] + ct * m12[0]
    q5 = math.atan2(s5, m00)
    q4 = math.atan2(m10_, -m20)
    q6 = math.atan2(m01, m02)
    return ((q4, q5, q6), (wrap_angle(q4 + math.pi, include_pi=True), -q5, wrap_angle(q6 + math.pi, include_pi=True)))


def _wrists_in_limits(
    wrists: tuple[tuple[float, float, float], ...], lims: Limits, bad: list[tuple[int, float]]
) -> list[tuple[float, float, float]]:
    """The wrist branches inside J4-J6's limits (fitted onto them); each other one's first joint outside goes to ``bad``."""
    l4, l5, l6 = lims[3], lims[4], lims[5]
    out = []
    for q4r, q5r, q6r in wrists:
        q4 = q4r if l4[0] <= q4r <= l4[1] else _fit(q4r, l4)
        if q4 is None:
            bad.append((3, q4r))
            continue
        q5 = q5r if l5[0] <= q5r <= l5[1] else _fit(q5r, l5)
        if q5 is None:
            bad.append((4, q5r))
            continue
        q6 = q6r if l6[0] <= q6r <= l6[1] else _fit(q6r, l6)
        if q6 is None:
            bad.append((5, q6r))
            continue
        out.append((q4, q5, q6))
    return out


def _twins(q: list[float], lims: Limits, wide: list[int]) -> list[list[float]]:
    """The 2 pi twins of ``q`` its ``wide`` joints' ranges allow (rare: J6 at exactly +-180 deg, or a joint
    spanning more than a turn)."""
    twins = [
        (i, min(lims[i][1], max(lims[i][0], t2)))
        for i in wide
        for t2 in (q[i] - TWO_PI, q[i] + TWO_PI)
        if lims[i][0] - LIMIT_SLACK <= t2 <= lims[i][1] + LIMIT_SLACK
    ]
    return _twin_combinations(q, twins) if twins else []


def _twin_combinations(q: list[float], twins: list[tuple[int, float]]) -> list[list[float]]:
    """Every q with some of its joints replaced by their 2 pi twins (q itself excluded)."""
    combos = [q]
    for i, t in twins:
        combos += [c[:i] + [t] + c[i + 1 :] for c in combos if c[i] == q[i]]
    return combos[1:]


def _limit_reason(arm: ArmModel, n: int, bad: list[tuple[int, float]]) -> str:
    names = []
    for i, v in bad:
        s = (
            f"J{i + 1} at {degrees_text(wrap_angle(v, include_pi=True))} (limits {math.degrees(arm.lower[i]):.0f}.."
            f"{math.degrees(arm.upper[i]):.0f}\N{DEGREE SIGN})"
        )
        if s not in names:
            names.append(s)
    return f"all {n} solutions violate joint limits: " + ", ".join(names[:4]) + (" ..." if len(names) > 4 else "")


def _meca500_candidates(
    arm: ArmModel, p: Sequence[float], rot: Sequence[Sequence[float]], seed: Sequence[float]
) -> tuple[list[_Candidate], str]:
    inside, bad, n, reason = _meca500_branches(p, rot, seed, arm_constants(arm).limits)
    if reason:
        return [], reason
    if not inside:
        return [], _limit_reason(arm, n, bad)
    out: list[_Candidate] = []
    dropped = 0
    for q in inside:
        pe, re = pose_errors(arm, q, p, rot)
        if pe > POSITION_CHECK or re > ROTATION_CHECK:
            dropped += 1
            continue
        out.append(_Candidate(tuple(q), pe, re))
    if not out:
        return [], f"closed form: {dropped} in-limit solution(s) failed the FK check (a derivation bug)"
    return out, ""


def meca500_ik(
    arm: ArmModel, position: Sequence[float], rotation: Sequence[Sequence[float]], seed: Sequence[float] | None = None
) -> list[np.ndarray]:
    """Every in-limit Meca500 joint vector putting the flange at ``position`` with ``rotation`` (base frame).

    Nearest to ``seed`` (weighted joint distance, see :func:`joint_distance`)
    first; the seed also fixes q4 at the wrist singularity and q1 at the shoulder
    singularity. Each one passed an FK check through ``arm``. Raises
    :class:`NoIKSolution` when there is none.
    """
    if arm.description.name != _geo.NAME:
        raise ValueError(f"meca500_ik: arm is a {arm.description.name!r}, not a {_geo.NAME!r}")
    p = [float(v) for v in position]
    rot = np.asarray(rotation, float).tolist()
    s = default_seed(arm) if seed is None else [float(v) for v in seed]
    cands, reason = _meca500_candidates(arm, p, rot, s)
    if not cands:
        raise NoIKSolution(reason)
    cands.sort(key=lambda c: joint_distance(arm, c.q, s))
    return [np.array(c.q) for c in cands]


@dataclass(frozen=True, slots=True)
class ClosedForm:
    """A robot type's closed-form IK, and what position-only solving needs to know about the arm."""

    candidates: Callable[
        [ArmModel, Sequence[float], Sequence[Sequence[float]], Sequence[float]], tuple[list[_Candidate], str]
    ]
    """(arm, position, rotation, seed) -> FK-checked in-limit candidates, or [] and the reason."""
    shoulder: tuple[float, float, float]
    """Every reachable flange position lies within ``reach`` of this point (base frame)."""
    reach: float
    roll_joint: int | None
    """A joint that only rolls the flange about its own z axis (the flange origin is on its axis): with the
    orientation free it keeps the seed's angle, since it cannot move the flange."""


CLOSED_FORMS: dict[str, ClosedForm] = {
    _geo.NAME: ClosedForm(
        _meca500_candidates, (0.0, 0.0, _MECA.shoulder_z), _MECA.reach_max + _MECA.wrist_to_flange, roll_joint=5
    ),
}
"""Robot type -> closed-form solver; :func:`~compute_peer.kinematics.ik.solve` uses it for method "auto" and "closed_form"."""
