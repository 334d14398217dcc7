"""Numerical IK for any arm: Levenberg-Marquardt inside the joint limits, with seeded restarts."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from .ik_common import default_seed, degrees_text
from .model import ArmModel, NoIKSolution


ACCEPT_POSITION = 1e-6
"""m: a start that stalls this close to the target is an answer (a micrometre; the solver aims at 1e-9 m)."""
ACCEPT_ROTATION = 1e-6
"""rad: the same for the orientation."""


def solve_numerical(
    arm: ArmModel,
    position: Sequence[float],
    rotation: Sequence[Sequence[float]] | None = None,
    seed: Sequence[float] | None = None,
    *,
    restarts: int = 24,
    iters: int = 80,
    rng_seed: int = 0,
    position_tol: float = 1e-9,
    rotation_tol: float = 1e-8,
    orientation_scale: float = 0.1,
    accept_position: float = ACCEPT_POSITION,
    accept_rotation: float = ACCEPT_ROTATION,
) -> tuple[np.ndarray, float, float]:
    """Levenberg-Marquardt IK for any arm, inside the joint limits; returns (q, position err, rotation err).

    Errors are the target's position minus the flange's, and log3(R_target R^T)
    (world frame) scaled by ``orientation_scale`` m/rad so that both count alike.
    Steps are clamped to the limits; a joint resting on a limit that the error
    pushes further out is frozen for that step, so the others still converge.
    When a start stalls, the solver restarts from ``restarts`` random in-limit
    joint vectors drawn with ``rng_seed`` (deterministic), unless it stalled
    within ``accept_position`` and ``accept_rotation`` (near a singularity, such
    as the UR5's wrist at 0, the last digits come slowly): that answer is taken,
    its residual reported as it is. Raises
    :class:`NoIKSolution` with the best residual and the joints on limits.
    """
    model, data, fid = arm.model, arm.data, arm.frame_id
    lo, hi = arm.lower, arm.upper
    target = np.asarray(position, float)
    rt = None if rotation is None else np.asarray(rotation, float)
    q0 = default_seed(arm) if seed is None else seed
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
            jac, grad = _step_jacobian(arm, q, e, rt, orientation_scale)
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
        if pe <= accept_position and re <= accept_rotation:
            return q, pe, re
        if best is None or cost < best[0]:
            best = (cost, q, pe, re)
    assert best is not None
    _, q, pe, re = best
    raise _not_converged(arm, q, pe, None if rt is None else re, len(starts))


def _step_jacobian(
    arm: ArmModel, q: np.ndarray, e: np.ndarray, rt: np.ndarray | None, orientation_scale: float
) -> tuple[np.ndarray, np.ndarray]:
    """The residual's Jacobian at ``q`` and its gradient ``J^T e``, with each joint that rests on a limit the
    error pushes further out frozen (its column zero) for this step, so the others still converge."""
    model, data, fid, lo, hi = arm.model, arm.data, arm.frame_id, arm.lower, arm.upper
    jac = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)[: 3 if rt is None else 6]
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
    return jac, grad


def _not_converged(arm: ArmModel, q: np.ndarray, pe: float, re: float | None, starts: int) -> NoIKSolution:
    """The refusal: the best residual (rotation's only when one was asked) and the joints resting on a limit."""
    lo, hi = arm.lower, arm.upper
    at = [
        f"J{i + 1} at its {'lower' if q[i] <= lo[i] + 1e-9 else 'upper'} limit {degrees_text(q[i])}"
        for i in range(len(q))
        if q[i] <= lo[i] + 1e-9 or q[i] >= hi[i] - 1e-9
    ]
    what = f"{pe:.3g} m" + ("" if re is None else f", {re:.3g} rad")
    return NoIKSolution(
        f"numerical IK did not converge from {starts} starts: best residual {what}"
        + (f" ({', '.join(at)})" if at else "")
    )
