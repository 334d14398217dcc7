"""The dry build of a robot type: does the sim take it, and do the sim and the compute peer agree on its arm?

``robofabric robots add`` runs it on the type it just wrote, before anyone starts a world with it: the type's
MJCF attached in a world as the sim attaches it (:func:`sim_peer.physics.build.compile_model`), and, where Pinocchio is
installed, the compute peer's model of its URDF (:class:`compute_peer.kinematics.ArmModel`) asked for the flange
at random joints within the limits, against MuJoCo's ``flange`` site. Two compilers of one URDF that disagree
would give IK solutions the sim puts elsewhere: that is refused here, not found in class.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

import robots

AGREE = 1e-5
"""m and rad: the largest gap between the sim's flange and the compute peer's FK a type may have (the MJCF
MuJoCo writes rounds to 6 significant digits: a rotation such as the Panda's hand's 45 degrees is off by 1e-6 rad)."""


@dataclass(frozen=True, slots=True)
class DryBuild:
    """The dry build's findings: the world's degrees of freedom and the FK gap, the larger of the position's (m)
    and the rotation's (rad) (``None``: no Pinocchio here)."""

    nq: int
    fk_gap: float | None
    samples: int


def dry_build(directory: Path, *, samples: int = 20, rng_seed: int = 0) -> DryBuild:
    """Build a world holding the type in ``directory`` and compare the two FKs; :class:`robots.DescriptionError`
    saying what failed."""
    import mujoco

    from sim_peer.physics.build import compile_model
    from sim_peer.physics.errors import WorldError

    desc = robots.load(str(directory))
    scene = robots.scene("arm_cell")
    placed = robots.SceneRobot(desc.name, "dry", (0.0, 0.0, 0.0, 0.0))  # at the world's origin: both FKs in one frame
    try:
        model = compile_model(scene, [placed], {"dry": desc})
    except WorldError as exc:
        raise robots.DescriptionError(f"the sim cannot build a world with {desc.name}: {exc}") from None
    try:
        from compute_peer.kinematics.ik_common import rotation_error
        from compute_peer.kinematics.model import ArmModel
    except ImportError:  # a sim-only install: the compute peer's check waits for a machine that has it
        return DryBuild(model.nq, None, 0)
    try:
        arm = ArmModel(str(directory))
    except ValueError as exc:
        raise robots.DescriptionError(f"the compute peer cannot model {desc.name}: {exc}") from None
    data = mujoco.MjData(model)
    site = model.site(f"dry/{desc.flange_site}").id
    rng = np.random.default_rng(rng_seed)
    gap = 0.0
    for _ in range(samples):
        q = rng.uniform(arm.lower, arm.upper)
        for name, v in zip(desc.joint_names, q):
            data.qpos[model.joint(f"dry/{name}").qposadr[0]] = v
        mujoco.mj_kinematics(model, data)
        m = arm.fk(q)
        gap = max(
            gap,
            float(np.linalg.norm(data.site_xpos[site] - m.translation)),
            rotation_error(data.site_xmat[site].reshape(3, 3), m.rotation),
        )
    if gap > AGREE:
        raise robots.DescriptionError(
            f"the sim's flange and the compute peer's FK of {desc.name} differ by {gap:.3g} "
            f"(m or rad, > {AGREE:g}): the MJCF and the URDF disagree"
        )
    return DryBuild(model.nq, gap, samples)


__all__ = ["AGREE", "DryBuild", "dry_build"]
