"""Inverse kinematics: a closed form for the Meca500 and a numerical solver for any arm.

:func:`solve` is the one entry point (the service layer calls it). It takes a
flange target in the arm's base frame, a position and optionally a quaternion
(w, x, y, z), and returns an :class:`IKSolution` inside the joint limits or
raises :class:`~compute_peer.kinematics.model.Unreachable` saying why; it never
returns a best effort. Malformed input (wrong shapes, NaN) raises plain
``ValueError``.

The Meca500 has a spherical wrist, so its IK splits into a position problem for
the wrist centre (J1-J3) and an orientation problem for the wrist (J4-J6), each
with two branches: up to 8 solutions, plus 2 pi twins of joints whose range
allows them (J6 spans +-180 deg). Every dimension comes from
:mod:`robots.meca500.geometry`, and every returned solution is checked by forward
kinematics through Pinocchio, which catches a derivation slip instead of
returning a wrong pose.

Targets inside the base column (the description's ``base_radius``, up to J1)
are refused for every method: kinematics alone would fold the arm over its base.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from robots.meca500 import geometry as _geo

from .model import ArmModel, Unreachable

TWO_PI = 2.0 * math.pi

POSITION_CHECK = 1e-9
"""m: a closed-form solution whose FK misses the target by more is a bug, and is dropped."""
ROTATION_CHECK = 1e-8
"""rad: the same for orientation."""
LIMIT_SLACK = 1e-9
"""rad: a joint this close outside a limit is rounding, and is clamped onto it."""
WRIST_SINGULAR = 1e-9
"""sin(q5) below this: J4 and J6 are one rotation; J4 keeps the seed's value."""
SHOULDER_SINGULAR = 1e-10
"""m: a wrist centre this close to the J1 axis leaves q1 free; it keeps the seed's value."""

METHODS = ("auto", "closed_form", "numerical", "casadi")


@dataclass(frozen=True, slots=True)
class IKSolution:
    """One joint vector reaching the target, how it was found and how well FK agrees."""

    q: np.ndarray  # joint angles (rad), within limits; read-only
    solver: str  # "closed_form" | "numerical" | "casadi"
    position_error: float  # m, from FK of q
    orientation_error: float  # rad (0.0 for position-only targets)
    candidates: int  # in-limit solutions the closed form found (0 for numerical)


# --------------------------------------------------------------------------- small math helpers


def quaternion_to_matrix(w: float, x: float, y: float, z: float) -> tuple[tuple[float, ...], ...]:
    """Rotation matrix (row tuples) of a unit quaternion (w, x, y, z)."""
    return (
        (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)),
    )


def _wrap(a: float) -> float:
    """Angle in (-pi, pi]."""
    a = math.fmod(a, TWO_PI)
    if a > math.pi:
        a -= TWO_PI
    elif a <= -math.pi:
        a += TWO_PI
    return a


@dataclass(frozen=True, slots=True)
class _ArmConstants:
    """Per-arm lists read once: plain floats, because the closed form's budget is ~100 us."""

    limits: tuple[tuple[float, float, bool], ...]  # lower, upper, spans a full turn (2 pi twins possible)
    weights: tuple[float, ...]


_CONSTANTS: weakref.WeakKeyDictionary[ArmModel, _ArmConstants] = weakref.WeakKeyDictionary()


def _constants(arm: ArmModel) -> _ArmConstants:
    c = _CONSTANTS.get(arm)
    if c is None:
        lo, hi = arm.lower.tolist(), arm.upper.tolist()
        limits = tuple((a, b, b - a >= TWO_PI - 2 * LIMIT_SLACK) for a, b in zip(lo, hi))
        c = _CONSTANTS[arm] = _ArmConstants(limits, tuple(_weights(arm)))
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
    return sum((w * (a - b)) ** 2 for w, a, b in zip(_constants(arm).weights, q, seed))


def _pose_errors(arm: ArmModel, q: Sequence[float], p: Sequence[float],
                 rot: Sequence[Sequence[float]] | None) -> tuple[float, float]:
    """FK of ``q`` through the arm's Pinocchio model (what :meth:`ArmModel.fk` does, minus the copy)."""
    pin.framesForwardKinematics(arm.model, arm.data, np.array(q, dtype=float))
    m = arm.data.oMf[arm.frame_id]
    t = m.translation.tolist()
    pe = math.sqrt((t[0] - p[0]) ** 2 + (t[1] - p[1]) ** 2 + (t[2] - p[2]) ** 2)
    if rot is None:
        return pe, 0.0
    # angle from |A - B|_F = 2 sqrt(2) sin(angle / 2): acos((trace - 1) / 2) cannot resolve angles below ~1e-8 rad
    (a0, a1, a2), (b0, b1, b2), (c0, c1, c2) = m.rotation.tolist()
    (x0, x1, x2), (y0, y1, y2), (z0, z1, z2) = rot
    s = ((a0 - x0) ** 2 + (a1 - x1) ** 2 + (a2 - x2) ** 2 + (b0 - y0) ** 2 + (b1 - y1) ** 2
         + (b2 - y2) ** 2 + (c0 - z0) ** 2 + (c1 - z1) ** 2 + (c2 - z2) ** 2)
    return pe, 2.0 * math.asin(min(1.0, math.sqrt(s) / (2.0 * math.sqrt(2.0))))


def _deg(a: float) -> str:
    return f"{math.degrees(a):.1f}\N{DEGREE SIGN}"


# --------------------------------------------------------------------------- Meca500 closed form


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


def _meca500_branches(p: Sequence[float], rot: Sequence[Sequence[float]], seed: Sequence[float],
                      lims: tuple[tuple[float, float, bool], ...]
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
    """
    g = _MECA
    f = g.flange
    (f00, f01, f02), (f10, f11, f12), (f20, f21, f22) = f
    # R6 = R Rf^T (row i, column j = sum_k R[i][k] Rf[j][k]), unrolled: plain floats are ~10x faster than numpy here
    r6 = [(a0 * f00 + a1 * f01 + a2 * f02, a0 * f10 + a1 * f11 + a2 * f12, a0 * f20 + a1 * f21 + a2 * f22)
          for a0, a1, a2 in rot]
    w = g.wrist_to_flange
    cx, cy, cz = p[0] - w * r6[0][0], p[1] - w * r6[1][0], p[2] - w * r6[2][0]
    r = math.hypot(cx, cy)
    h = cz - g.shoulder_z
    dist = math.hypot(r, h)
    if dist > g.reach_max * (1 + 1e-12):
        return [], [], 0, f"out of reach: wrist centre {dist:.4f} m from the shoulder > max {g.reach_max:.4f} m"
    if dist < g.reach_min * (1 - 1e-12):
        return [], [], 0, f"too close: wrist centre {dist:.4f} m from the shoulder < min {g.reach_min:.4f} m"
    if r < SHOULDER_SINGULAR:
        q1a = seed[0]
        u = cx * math.cos(q1a) + cy * math.sin(q1a)
    else:
        q1a, u = math.atan2(cy, cx), r
    l2, a, b = g.upper_arm, g.forearm_x, g.forearm_z
    d = math.hypot(a, b)
    # b c3 - a s3 = d cos(q3 + phi) = k
    k = (dist * dist - l2 * l2 - d * d) / (2.0 * l2)
    t = math.acos(max(-1.0, min(1.0, k / d)))
    elbows = (t - g.elbow_phi,) if t < 1e-12 else (t - g.elbow_phi, -t - g.elbow_phi)
    inside: list[list[float]] = []
    bad: list[tuple[int, float]] = []
    n = 0
    l1, l2lim, l3, l4, l5, l6 = lims
    wide = [i for i, lim in enumerate(lims) if lim[2]]
    # below, "v if lo <= v <= hi else _fit(v, lim)" inlines the common case: ~25 calls saved per solve
    for q1raw, uu in ((q1a, u), (_wrap(q1a + math.pi), -u)):
        q1 = q1raw if l1[0] <= q1raw <= l1[1] else _fit(q1raw, l1)
        if q1 is None:
            n += 2 * len(elbows)
            bad.append((0, q1raw))
            continue
        c1, s1 = math.cos(q1), math.sin(q1)
        # link 6 rotation seen after J1: Rz(-q1) R6
        (x0, x1, x2), (y0, y1, y2) = r6[0], r6[1]
        m10 = (c1 * x0 + s1 * y0, c1 * x1 + s1 * y1, c1 * x2 + s1 * y2)
        m11 = (c1 * y0 - s1 * x0, c1 * y1 - s1 * x1, c1 * y2 - s1 * x2)
        m12 = r6[2]
        for q3r in elbows:
            n += 2
            q3w = _wrap(q3r)
            c3, s3 = math.cos(q3w), math.sin(q3w)
            vx, vz = a * c3 + b * s3, l2 - a * s3 + b * c3
            q2w = _wrap(math.atan2(vz, vx) - math.atan2(h, uu))
            q2 = q2w if l2lim[0] <= q2w <= l2lim[1] else _fit(q2w, l2lim)
            if q2 is None:
                bad.append((1, q2w))
                continue
            q3 = q3w if l3[0] <= q3w <= l3[1] else _fit(q3w, l3)
            if q3 is None:
                bad.append((2, q3w))
                continue
            th = q2 + q3
            ct, st = math.cos(th), math.sin(th)
            # M = Ry(th)^T (Rz(-q1) R6); only the entries the X-Y-X angles need
            m00 = ct * m10[0] - st * m12[0]
            m01 = ct * m10[1] - st * m12[1]
            m02 = ct * m10[2] - st * m12[2]
            m10_, m20 = m11[0], st * m10[0] + ct * m12[0]
            s5 = math.hypot(m01, m02)
            if s5 < WRIST_SINGULAR:
                n -= 1  # J4 and J6 merge: one wrist branch, not two
                m11_, m21 = m11[1], st * m10[1] + ct * m12[1]
                q4 = seed[3]
                if m00 > 0:  # q5 = 0: Rx(q4 + q6)
                    q5 = math.atan2(s5, m00)
                    q6 = _wrap(math.atan2(m21, m11_) - q4)
                else:  # q5 = pi (outside the Meca500's J5 range; kept for completeness): Rx(q4 - q6)
                    q5 = math.pi
                    q6 = _wrap(q4 - math.atan2(m21, m11_))
                wrists = ((q4, q5, q6),)
            else:
                q5 = math.atan2(s5, m00)
                q4 = math.atan2(m10_, -m20)
                q6 = math.atan2(m01, m02)
                wrists = ((q4, q5, q6), (_wrap(q4 + math.pi), -q5, _wrap(q6 + math.pi)))
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
                q = [q1, q2, q3, q4, q5, q6]
                inside.append(q)
                if wide:
                    twins = [(i, min(lims[i][1], max(lims[i][0], t2))) for i in wide for t2 in (q[i] - TWO_PI, q[i] + TWO_PI)
                             if lims[i][0] - LIMIT_SLACK <= t2 <= lims[i][1] + LIMIT_SLACK]
                    if twins:  # rare: J6 at exactly +-180 deg, or a joint spanning more than a turn
                        inside.extend(_twin_combinations(q, twins))
    return inside, bad, n, ""


def _twin_combinations(q: list[float], twins: list[tuple[int, float]]) -> list[list[float]]:
    """Every q with some of its joints replaced by their 2 pi twins (q itself excluded)."""
    combos = [q]
    for i, t in twins:
        combos += [c[:i] + [t] + c[i + 1:] for c in combos if c[i] == q[i]]
    return combos[1:]


def _limit_reason(arm: ArmModel, n: int, bad: list[tuple[int, float]]) -> str:
    names = []
    for i, v in bad:
        s = (f"J{i + 1} at {_deg(_wrap(v))} (limits {math.degrees(arm.lower[i]):.0f}.."
             f"{math.degrees(arm.upper[i]):.0f}\N{DEGREE SIGN})")
        if s not in names:
            names.append(s)
    return f"all {n} solutions violate joint limits: " + ", ".join(names[:4]) + (" ..." if len(names) > 4 else "")


def _meca500_candidates(arm: ArmModel, p: Sequence[float], rot: Sequence[Sequence[float]],
                        seed: Sequence[float]) -> tuple[list[_Candidate], str]:
    inside, bad, n, reason = _meca500_branches(p, rot, seed, _constants(arm).limits)
    if reason:
        return [], reason
    if not inside:
        return [], _limit_reason(arm, n, bad)
    out: list[_Candidate] = []
    dropped = 0
    for q in inside:
        pe, re = _pose_errors(arm, q, p, rot)
        if pe > POSITION_CHECK or re > ROTATION_CHECK:
            dropped += 1
            continue
        out.append(_Candidate(tuple(q), pe, re))
    if not out:
        return [], f"closed form: {dropped} in-limit solution(s) failed the FK check (a derivation bug)"
    return out, ""


def meca500_ik(arm: ArmModel, position: Sequence[float], rotation: Sequence[Sequence[float]],
               seed: Sequence[float] | None = None) -> list[np.ndarray]:
    """Every in-limit Meca500 joint vector putting the flange at ``position`` with ``rotation`` (base frame).

    Nearest to ``seed`` (weighted joint distance, see :func:`joint_distance`)
    first; the seed also fixes q4 at the wrist singularity and q1 at the shoulder
    singularity. Each one passed an FK check through ``arm``. Raises
    :class:`Unreachable` when there is none.
    """
    if arm.description.name != _geo.NAME:
        raise ValueError(f"meca500_ik: arm is a {arm.description.name!r}, not a {_geo.NAME!r}")
    p = [float(v) for v in position]
    rot = np.asarray(rotation, float).tolist()
    s = _default_seed(arm) if seed is None else [float(v) for v in seed]
    cands, reason = _meca500_candidates(arm, p, rot, s)
    if not cands:
        raise Unreachable(reason)
    cands.sort(key=lambda c: joint_distance(arm, c.q, s))
    return [np.array(c.q) for c in cands]


@dataclass(frozen=True, slots=True)
class ClosedForm:
    """A robot type's closed-form IK, and what position-only solving needs to know about the arm."""

    candidates: Callable[[ArmModel, Sequence[float], Sequence[Sequence[float]], Sequence[float]],
                         tuple[list[_Candidate], str]]
    """(arm, position, rotation, seed) -> FK-checked in-limit candidates, or [] and the reason."""
    shoulder: tuple[float, float, float]
    """Every reachable flange position lies within ``reach`` of this point (base frame)."""
    reach: float
    roll_joint: int | None
    """A joint that only rolls the flange about its own z axis (the flange origin is on its axis): with the
    orientation free it keeps the seed's angle, since it cannot move the flange."""


CLOSED_FORMS: dict[str, ClosedForm] = {
    _geo.NAME: ClosedForm(_meca500_candidates, (0.0, 0.0, _MECA.shoulder_z),
                          _MECA.reach_max + _MECA.wrist_to_flange, roll_joint=5),
}
"""Robot type -> closed-form solver; :func:`solve` uses it for method "auto" and "closed_form"."""


def nearest(arm: ArmModel, solutions: Sequence[Sequence[float]], seed: Sequence[float]) -> int:
    """Index of the solution nearest ``seed`` in weighted joint distance."""
    if not solutions:
        raise ValueError("no solutions to choose from")
    w = _constants(arm).weights
    ws = [wi * b for wi, b in zip(w, seed)]
    d = [math.dist([wi * a for wi, a in zip(w, q)], ws) for q in solutions]
    return d.index(min(d))


# --------------------------------------------------------------------------- numerical


def solve_numerical(arm: ArmModel, position: Sequence[float], rotation: Sequence[Sequence[float]] | None = None,
                    seed: Sequence[float] | None = None, *, restarts: int = 24, iters: int = 80,
                    rng_seed: int = 0, position_tol: float = 1e-9, rotation_tol: float = 1e-8,
                    orientation_scale: float = 0.1) -> tuple[np.ndarray, float, float]:
    """Levenberg-Marquardt IK for any arm, inside the joint limits; returns (q, position err, rotation err).

    Errors are the target's position minus the flange's, and log3(R_target R^T)
    (world frame) scaled by ``orientation_scale`` m/rad so that both count alike.
    Steps are clamped to the limits; a joint resting on a limit that the error
    pushes further out is frozen for that step, so the others still converge.
    When a start stalls, the solver restarts from ``restarts`` random in-limit
    joint vectors drawn with ``rng_seed`` (deterministic). Raises
    :class:`Unreachable` with the best residual and the joints on limits.
    """
    model, data, fid = arm.model, arm.data, arm.frame_id
    lo, hi = arm.lower, arm.upper
    target = np.asarray(position, float)
    rt = None if rotation is None else np.asarray(rotation, float)
    rows = 3 if rt is None else 6
    q0 = _default_seed(arm) if seed is None else seed
    rng = np.random.default_rng(rng_seed)
    starts = [np.clip(np.asarray(q0, float), lo, hi)]
    starts += [rng.uniform(lo, hi) for _ in range(restarts)]
    best: tuple[float, np.ndarray, float, float] | None = None
    eye = np.eye(model.nq)

    def residual(q: np.ndarray) -> tuple[np.ndarray, float, float]:
        pin.framesForwardKinematics(model, data, q)
        m = data.oMf[fid]
        ep = target - m.translation
        if rt is None:
            return ep, float(np.linalg.norm(ep)), 0.0
        er = pin.log3(rt @ m.rotation.T)
        return np.concatenate([ep, orientation_scale * er]), float(np.linalg.norm(ep)), float(np.linalg.norm(er))

    for q in starts:
        q = q.copy()
        e, pe, re = residual(q)
        cost = checkpoint = float(e @ e)
        lam = 1e-3
        for it in range(iters):
            if pe <= position_tol and re <= rotation_tol:
                return q, pe, re
            if it and it % 10 == 0:
                if cost > 0.5 * checkpoint:
                    break  # crawling (a limit, a local minimum): a fresh start is cheaper
                checkpoint = cost
            jac = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)[:rows]
            if rt is not None:
                # e_r = log3(R_t R^T); turning the flange by w (world) changes it by -Jlog3(R_t R^T) w
                jac = jac.copy()
                jac[3:] = orientation_scale * (pin.Jlog3(rt @ data.oMf[fid].rotation.T) @ jac[3:])
            grad = jac.T @ e
            frozen = ((q <= lo + 1e-12) & (grad < 0)) | ((q >= hi - 1e-12) & (grad > 0))
            if frozen.any():
                jac = jac.copy()
                jac[:, frozen] = 0.0
                grad = jac.T @ e
            jtj = jac.T @ jac
            while True:
                dq = np.linalg.solve(jtj + lam * (eye + np.diag(np.diag(jtj))), grad)
                qn = np.clip(q + dq, lo, hi)
                en, pen, ren = residual(qn)
                cn = float(en @ en)
                if cn < cost:
                    q, e, pe, re, cost = qn, en, pen, ren, cn
                    lam = max(lam / 3.0, 1e-12)
                    break
                lam *= 4.0
                if lam > 1e6:
                    break
            if lam > 1e6:
                break  # stalled: a local minimum or a limit; restart
        if pe <= position_tol and re <= rotation_tol:
            return q, pe, re
        if best is None or cost < best[0]:
            best = (cost, q, pe, re)
    assert best is not None
    _, q, pe, re = best
    at = [f"J{i + 1} at its {'lower' if q[i] <= lo[i] + 1e-9 else 'upper'} limit {_deg(q[i])}"
          for i in range(len(q)) if q[i] <= lo[i] + 1e-9 or q[i] >= hi[i] - 1e-9]
    what = f"{pe:.3g} m" + ("" if rt is None else f", {re:.3g} rad")
    raise Unreachable(f"numerical IK did not converge from {len(starts)} starts: best residual {what}"
                      + (f" ({', '.join(at)})" if at else ""))


# --------------------------------------------------------------------------- entry point


def _default_seed(arm: ArmModel) -> list[float]:
    """The zero pose clamped into the limits: what a seedless request is nearest to."""
    return np.clip(np.zeros(arm.model.nq), arm.lower, arm.upper).tolist()


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
        options.append((f"tilted {elevation:+.0f}/{azimuth:+.0f} deg", _tool_frame(phi + math.radians(azimuth), math.radians(elevation))))
    return options


TILTS = ((-45.0, 0.0), (45.0, 0.0), (-60.0, 45.0), (-60.0, -45.0), (0.0, 60.0), (0.0, -60.0), (70.0, 0.0), (-20.0, 0.0))
"""(elevation, azimuth from radial) of the extra tool directions tried for position-only targets, in degrees."""


def _tool_frame(azimuth: float, elevation: float) -> list[list[float]]:
    """A flange rotation whose z (the tool) points at ``azimuth`` / ``elevation``; x in the vertical plane."""
    ca, sa, ce, se = math.cos(azimuth), math.sin(azimuth), math.cos(elevation), math.sin(elevation)
    z = (ce * ca, ce * sa, se)
    x = (se * ca, se * sa, -ce)  # perpendicular to z, pointing down-ish like Mecademic's convention
    y = (z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0])
    return [[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]]


def _keep_roll(arm: ArmModel, q: tuple[float, ...], joint: int | None, seed: list[float],
               p: list[float]) -> tuple[tuple[float, ...], float] | None:
    """``q`` with the roll joint at the seed's angle, and its position error (FK); None if FK disagrees."""
    if joint is not None:
        v = min(arm.upper[joint], max(arm.lower[joint], seed[joint]))
        q = q[:joint] + (float(v),) + q[joint + 1:]
    pe, _ = _pose_errors(arm, q, p, None)
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
        raise Unreachable(f"inside the base column: {math.hypot(p[0], p[1]):.3f} m from its axis < radius "
                          f"{radius:.3f} m, {p[2]:.3f} m high < top {top:.3f} m")


def solve(arm: ArmModel, position: Sequence[float], quaternion: Sequence[float] | None = None,
          seed: Sequence[float] | None = None, *, method: str = "auto") -> IKSolution:
    """Joint angles putting ``arm``'s flange at ``position`` (and ``quaternion``, w x y z), base frame.

    ``method``: "auto" (the robot type's closed form if it has one, else
    numerical), "closed_form", "numerical" or "casadi" (IPOPT, hard joint limits:
    :mod:`~compute_peer.kinematics.casadi_ik`). The result is the solution nearest
    ``seed`` (default: the zero pose) in weighted joint distance. Without a
    quaternion the orientation is free: the closed form tries the seed's flange
    orientation, then the tool pointing down, then horizontal and radially
    outward, then falls back to numerical position-only IK from the seed; the
    closed form keeps the roll joint (J6) at the seed's angle, as it cannot move
    the flange. Raises :class:`Unreachable` (with the reason) when nothing inside the limits
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
        s = _default_seed(arm)
    else:  # a seed is a hint (often a measured state a hair past a limit): clamp it, don't refuse it
        s = [min(hi, max(lo, v)) for v, (lo, hi, _) in zip(_vector("seed", seed, nq), _constants(arm).limits)]
    _refuse_base_column(arm, p)
    closed = CLOSED_FORMS.get(arm.description.name)
    if method == "closed_form" and closed is None:
        raise ValueError(f"robot type {arm.description.name!r} has no closed-form IK")
    if method == "casadi":
        from .casadi_ik import solve_casadi  # imports CasADi on first use only

        q, pe, re = solve_casadi(arm, p, rot, s)
        return _solution(q, "casadi", pe, re, 0)
    if method == "numerical" or closed is None:
        q, pe, re = solve_numerical(arm, p, rot, s)
        return _solution(q, "numerical", pe, re, 0)
    if rot is not None:
        cands, reason = closed.candidates(arm, p, rot, s)
        if not cands:
            raise Unreachable(reason)
        best = cands[nearest(arm, [c.q for c in cands], s)]
        return _solution(best.q, "closed_form", best.position_error, best.orientation_error, len(cands))
    return _solve_position_closed(arm, closed, p, s)


def _solve_position_closed(arm: ArmModel, closed: ClosedForm, p: list[float], s: list[float]) -> IKSolution:
    dist = math.dist(p, closed.shoulder)
    if dist > closed.reach:
        raise Unreachable(f"out of reach: distance to shoulder {dist:.4f} m > max {closed.reach:.4f} m")
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
    except Unreachable as exc:
        raise Unreachable(f"{exc}; closed form: " + "; ".join(reasons)) from None
    return _solution(q, "numerical", pe, 0.0, 0)


def _solution(q: Sequence[float], solver: str, pe: float, re: float, n: int) -> IKSolution:
    arr = np.array(q, dtype=float)
    arr.flags.writeable = False
    return IKSolution(arr, solver, float(pe), float(re), n)
