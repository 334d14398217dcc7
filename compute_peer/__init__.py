"""The compute peer: what MATLAB did in the paper, served over Zenoh.

:mod:`.kinematics` (Pinocchio arm models, the Meca500's closed-form IK, a
numerical IK for any arm, Jacobians and the Eq. 7 speeds) and
:mod:`.navigation` (log-odds mapping, Hybrid A* and OMPL planning) are pure
cores; their ``service`` modules put them on the fabric as ``srv/{ik,fk,
jacobian,map,plan}`` queryables; :mod:`.peer` hosts both on one session and
:mod:`.cli` is ``robofabric compute``. Its message types live in :mod:`fabric.interfaces`.
"""
