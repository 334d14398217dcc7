"""IK as a small nonlinear program: CasADi (symbolic forward kinematics) and IPOPT.

The forward kinematics is written out in CasADi SX from the arm's Pinocchio
model (``pinocchio.casadi`` is not in the pinned wheel): for each joint its
placement in the parent joint's frame, times the joint's own motion (a
rotation about, or a translation along, its axis), then the flange frame's
placement in its parent joint's frame. The program, for a target position p*
and optionally a rotation R*::

    minimise    sum_i w_i (q_i - seed_i)^2        w_i = 1 / max_speed_i^2
    subject to  lower <= q <= upper                (hard bounds, never clamped afterwards)
                p(q) = p*
                vee(E - E^T) / 2 = 0,  trace(E) >= 1,   E = R*^T R(q)   (with an orientation)

``vee(E - E^T) / 2`` is sin(angle) times the axis of the residual rotation: it
is linear in the angle near zero (exact convergence, no square root), and the
trace inequality (angle <= 90 deg) rules out its other root, a half turn.

IPOPT started off the solution set with these equality constraints often
declares them infeasible (about two starts in three from a random seed on the
Meca500), so each start first minimises the least-squares residual
|p - p*|^2 / (0.1 m)^2 + |R - R*|_F^2 within the bounds (a small initial barrier
parameter, so a start already on target stays there), and the program above
then runs from that point. The answer is a local minimum of the seed distance
on the solution set, reached from the seed, not a global one: a 6-joint arm's
full-pose solutions are isolated points, so there it is whichever one the
residual descent reaches (from a seed near a solution, that one; from random
seeds on the Meca500, the closed form's nearest about half the time).

Two ``nlpsol`` per robot type and target kind (full pose / position only) are
built on first use; targets and seed are parameters, so a solve does not
rebuild anything. Every answer is checked by Pinocchio's FK and the limits; a
failed start is retried from seeded random in-limit starts (deterministic),
then :class:`~compute_peer.kinematics.model.NoIKSolution` is raised with IPOPT's
status and the best residuals.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence

import casadi as ca
import numpy as np

from .ik_common import degrees_text, rotation_error
from .model import ArmModel, NoIKSolution

POSITION_TOL = 1e-6
"""m: an answer whose FK misses the target position by more is rejected."""
ROTATION_TOL = 1e-6
"""rad: the same for the orientation."""
RESTARTS = 20
"""Seeded random in-limit starts tried after the seed's own start fails (each succeeds about a third of the time)."""
RESIDUAL_LENGTH = 0.1
"""m: the position residual's scale against the rotation's (Frobenius) in the least-squares start."""

IPOPT_OPTIONS = {
    "print_time": False,
    "ipopt.print_level": 0,
    "ipopt.sb": "yes",
    "ipopt.max_iter": 100,
    "ipopt.tol": 1e-12,
    "ipopt.constr_viol_tol": 1e-10,
    "ipopt.bound_relax_factor": 0.0,  # joint limits are hard: no relaxed bounds to clamp back afterwards
}
FEASIBILITY_OPTIONS = {"ipopt.tol": 1e-14, "ipopt.mu_init": 1e-6}
"""The least-squares start converges to a zero residual: a tighter tolerance costs an iteration or two."""

_REVOLUTE = {"JointModelRX": (1.0, 0.0, 0.0), "JointModelRY": (0.0, 1.0, 0.0), "JointModelRZ": (0.0, 0.0, 1.0)}
_PRISMATIC = {"JointModelPX": (1.0, 0.0, 0.0), "JointModelPY": (0.0, 1.0, 0.0), "JointModelPZ": (0.0, 0.0, 1.0)}


def _rotation(axis: Sequence[float], angle: ca.SX) -> ca.SX:
    """Rodrigues: the rotation by ``angle`` about the unit ``axis`` (numbers), symbolic in the angle."""
    x, y, z = (float(a) for a in axis)
    k = ca.DM([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return ca.DM.eye(3) + ca.sin(angle) * k + (1.0 - ca.cos(angle)) * ca.mtimes(k, k)


def _joint_motion(model, i: int, q: ca.SX) -> tuple[ca.SX, ca.SX]:
    """(rotation, translation) of joint ``i``'s own motion, or ValueError for a joint type not handled here."""
    jm = model.joints[i]
    kind = jm.shortname()
    if jm.nq != 1:
        raise ValueError(
            f"casadi IK: joint {model.names[i]!r} is a {kind} ({jm.nq} configuration values); "
            "only 1-dof revolute and prismatic joints are supported"
        )
    v = q[jm.idx_q]
    if kind in _REVOLUTE or kind == "JointModelRevoluteUnaligned":
        axis = _REVOLUTE.get(kind) or jm.extract().axis
        return _rotation(axis, v), ca.SX.zeros(3, 1)
    if kind in _PRISMATIC or kind == "JointModelPrismaticUnaligned":
        axis = _PRISMATIC.get(kind) or jm.extract().axis
        return ca.SX.eye(3), ca.DM([float(a) for a in axis]) * v
    raise ValueError(
        f"casadi IK: joint {model.names[i]!r} is a {kind}; "
        "only revolute (RX/RY/RZ/unaligned) and prismatic joints are supported"
    )


def symbolic_fk(arm: ArmModel) -> ca.Function:
    """``fk(q) -> (position 3x1, rotation 3x3)`` of the flange, as a CasADi function built from the Pinocchio model."""
    model = arm.model
    q = ca.SX.sym("q", model.nq)
    rot: list[ca.SX] = [ca.SX.eye(3)]
    pos: list[ca.SX] = [ca.SX.zeros(3, 1)]
    for i in range(1, model.njoints):
        parent = model.parents[i]
        m = model.jointPlacements[i]
        r0 = ca.mtimes(rot[parent], ca.DM(m.rotation))
        p0 = pos[parent] + ca.mtimes(rot[parent], ca.DM(m.translation))
        rj, pj = _joint_motion(model, i, q)
        rot.append(ca.mtimes(r0, rj))
        pos.append(p0 + ca.mtimes(r0, pj))
    frame = model.frames[arm.frame_id]
    j = frame.parentJoint
    r = ca.mtimes(rot[j], ca.DM(frame.placement.rotation))
    p = pos[j] + ca.mtimes(rot[j], ca.DM(frame.placement.translation))
    return ca.Function("fk", [q], [p, r], ["q"], ["position", "rotation"])


class CasadiIK:
    """One robot type's symbolic FK and its two IPOPT programs (full pose, position only), built once."""

    def __init__(self, arm: ArmModel) -> None:
        model = arm.model
        self.fk = symbolic_fk(arm)  # first: it names a joint type it cannot handle
        if model.nq != len(arm.lower) or model.nq != len(arm.upper):
            raise ValueError(f"casadi IK: the model has {model.nq} joints, the description's limits {len(arm.lower)}")
        self.name = arm.description.name
        self.nq = model.nq
        self.lower = np.asarray(arm.lower, float)
        self.upper = np.asarray(arm.upper, float)
        speeds = arm.description.max_speed
        if len(speeds) == self.nq and all(s > 0 for s in speeds):
            self.weights = np.array([1.0 / (s * s) for s in speeds])
        else:
            self.weights = np.ones(self.nq)
        self.reach = self._reach_bound(arm)
        self._solvers: dict[bool, tuple[ca.Function, ca.Function]] = {}
        self._lock = threading.Lock()

    @staticmethod
    def _reach_bound(arm: ArmModel) -> tuple[np.ndarray, float] | None:
        """(centre, radius): every flange position of an all-revolute chain lies in this ball; None otherwise."""
        model = arm.model
        if any(
            model.joints[i].shortname() not in (*_REVOLUTE, "JointModelRevoluteUnaligned")
            for i in range(1, model.njoints)
        ):
            return None
        frame = model.frames[arm.frame_id]
        chain, j = [], frame.parentJoint
        while j > 0:
            chain.append(j)
            j = model.parents[j]
        if not chain:
            return None
        first = chain[-1]  # the joint nearest the base: its own rotation does not move its origin
        centre = model.jointPlacements[first].translation.copy()
        if model.parents[first] != 0:
            return None
        radius = sum(float(np.linalg.norm(model.jointPlacements[i].translation)) for i in chain[:-1])
        radius += float(np.linalg.norm(frame.placement.translation))
        return centre, radius

    def _solvers_for(self, with_rotation: bool) -> tuple[ca.Function, ca.Function]:
        with self._lock:
            s = self._solvers.get(with_rotation)
            if s is None:
                s = self._solvers[with_rotation] = self._build(with_rotation)
            return s

    def _build(self, with_rotation: bool) -> tuple[ca.Function, ca.Function]:
        """(feasibility, nearest): the least-squares pose residual within the bounds, and the program above."""
        q = ca.SX.sym("q", self.nq)
        seed = ca.SX.sym("seed", self.nq)
        target = ca.SX.sym("target", 3)
        pos, rot = self.fk(q)
        d = q - seed
        residual = ca.sumsqr(pos - target) / RESIDUAL_LENGTH**2
        g = [pos - target]
        params = [seed, target]
        if with_rotation:
            rt = ca.SX.sym("rotation", 3, 3)
            e = ca.mtimes(rt.T, rot)
            g += [ca.vertcat(e[2, 1] - e[1, 2], e[0, 2] - e[2, 0], e[1, 0] - e[0, 1]) / 2, ca.trace(e)]
            residual += ca.sumsqr(rot - rt)
            params.append(ca.vec(rt))  # column-major, as numpy's reshape(order="F")
        p = ca.vertcat(*params)
        kind = "pose" if with_rotation else "position"
        feasible = ca.nlpsol(
            f"ik_{self.name}_{kind}_feasible",
            "ipopt",
            {"x": q, "p": p, "f": residual},
            IPOPT_OPTIONS | FEASIBILITY_OPTIONS,
        )
        nearest = ca.nlpsol(
            f"ik_{self.name}_{kind}",
            "ipopt",
            {"x": q, "p": p, "f": ca.dot(ca.DM(self.weights) * d, d), "g": ca.vertcat(*g)},
            IPOPT_OPTIONS,
        )
        return feasible, nearest

    def solve(
        self,
        arm: ArmModel,
        position: Sequence[float],
        rotation: Sequence[Sequence[float]] | None,
        seed: Sequence[float],
        *,
        restarts: int = RESTARTS,
        rng_seed: int = 0,
    ) -> tuple[np.ndarray, float, float]:
        """(q, position error m, rotation error rad) near ``seed``; every answer checked by ``arm``'s FK.

        Each start (the seed, then ``restarts`` random in-limit joint vectors
        drawn with ``rng_seed``) runs two IPOPT programs: the least-squares
        residual of the target within the bounds, which gets onto the solution
        set (IPOPT started off it often declares the constraints infeasible),
        then the nearest-to-the-seed program from that point. ``seed`` is clamped
        into the limits (``ik.solve`` already does). Raises :class:`NoIKSolution`
        with IPOPT's status and the best residuals.
        """
        p = np.asarray(position, float)
        rt = None if rotation is None else np.asarray(rotation, float)
        s = np.clip(np.asarray(seed, float), self.lower, self.upper)
        if self.reach is not None:
            centre, radius = self.reach
            dist = float(np.linalg.norm(p - centre))
            if dist > radius * (1 + 1e-9):
                raise NoIKSolution(f"out of reach: {dist:.4g} m from the first joint > the chain's {radius:.4f} m")
        ok, pe, re = self._check(arm, s, p, rt)
        if ok:  # the seed is on target: nothing is nearer (and IPOPT's barrier would only nudge it off)
            return s, pe, re
        feasible, nearest = self._solvers_for(rt is not None)
        params = np.concatenate([s, p] + ([] if rt is None else [rt.reshape(-1, order="F")]))
        lbg = [0.0] * 3 + ([] if rt is None else [0.0, 0.0, 0.0, 1.0])
        ubg = [0.0] * 3 + ([] if rt is None else [0.0, 0.0, 0.0, math.inf])
        bounds = {"lbx": self.lower, "ubx": self.upper}
        rng = np.random.default_rng(rng_seed)
        best: tuple[float, np.ndarray, float, float, str] | None = None
        tries = 0
        for k in range(restarts + 1):
            x0 = s if k == 0 else rng.uniform(self.lower, self.upper)
            tries += 1
            res = feasible(x0=x0, p=params, **bounds)
            q1 = np.asarray(res["x"], float).reshape(-1)
            status = "least squares: " + feasible.stats()["return_status"]
            ok1, pe, re = self._check(arm, q1, p, rt)
            if ok1:
                res = nearest(x0=q1, p=params, lbg=lbg, ubg=ubg, **bounds)
                q2 = np.asarray(res["x"], float).reshape(-1)
                ok2, pe2, re2 = self._check(arm, q2, p, rt)
                if ok2:
                    return q2, pe2, re2
                # the nearest-point program lost the solution it started on: the start is still a solution
                return q1, pe, re
            score = pe + 0.1 * re
            if best is None or score < best[0]:
                best = (score, q1, pe, re, status)
        assert best is not None
        _, q, pe, re, status = best
        at = [
            f"J{i + 1} at its {'lower' if q[i] <= self.lower[i] + 1e-6 else 'upper'} limit {degrees_text(q[i])}"
            for i in range(self.nq)
            if q[i] <= self.lower[i] + 1e-6 or q[i] >= self.upper[i] - 1e-6
        ]
        what = f"{pe:.3g} m" + ("" if rt is None else f", {re:.3g} rad")
        raise NoIKSolution(
            f"casadi IK found no solution within limits from {tries} starts (IPOPT {status}); "
            f"best residual {what}" + (f" ({', '.join(at)})" if at else "")
        )

    def _check(self, arm: ArmModel, q: np.ndarray, p: np.ndarray, rt: np.ndarray | None) -> tuple[bool, float, float]:
        """(within limits and on target, position error, rotation error) by Pinocchio's FK."""
        if not np.all(np.isfinite(q)):
            return False, math.inf, math.inf
        pe, re = self._errors(arm, q, p, rt)
        inside = bool(np.all(q >= self.lower) and np.all(q <= self.upper))
        return inside and pe <= POSITION_TOL and re <= ROTATION_TOL, pe, re

    @staticmethod
    def _errors(arm: ArmModel, q: np.ndarray, p: np.ndarray, rt: np.ndarray | None) -> tuple[float, float]:
        m = arm.fk(q)
        pe = float(np.linalg.norm(m.translation - p))
        return pe, (0.0 if rt is None else rotation_error(m.rotation, rt))


_CACHE: dict[tuple[str, str], CasadiIK] = {}
_CACHE_LOCK = threading.Lock()


def casadi_ik(arm: ArmModel) -> CasadiIK:
    """The robot type's :class:`CasadiIK`, built on first use (keyed by type name and URDF path)."""
    key = (arm.description.name, str(arm.description.urdf_path))
    with _CACHE_LOCK:
        c = _CACHE.get(key)
        if c is None:
            c = _CACHE[key] = CasadiIK(arm)
        return c


def solve_casadi(
    arm: ArmModel, position: Sequence[float], rotation: Sequence[Sequence[float]] | None, seed: Sequence[float], **kw
) -> tuple[np.ndarray, float, float]:
    """:meth:`CasadiIK.solve` on the arm's cached programs: (q, position error, rotation error)."""
    return casadi_ik(arm).solve(arm, position, rotation, seed, **kw)
