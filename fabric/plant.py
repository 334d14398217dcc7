"""Planted defects, for proving the soak's checker is not vacuous. TEST-ONLY: never set in a real world.

A defect is passed in, never read from the environment: ``robofabric bench soak --plant KIND`` starts its sims
with ``robofabric sim --plant KIND`` (a hidden option), which hands it to the ownership authority
(``Authority(plant=)``, which puts it in the state machine's ``OwnState.plant``) and to the replica host
(``ReplicaHost(plant=)``). The checker must then report a violation (robofabric/soak/checker.py;
tests/robofabric/soak/test_soak_plants.py). Every default is ``""``: no defect. The hooks, one line each:

* ``reset`` (sim_peer/replica/following.py, ``catch_up``): a standby taking the world over puts its robots back at
  their spawn pose instead of where the old authority left them;
* ``double-owner`` (ownership/state.py, a take-over of a still robot): the new owner gets the old owner's
  epoch, so two owners hold one epoch;
* ``stale-command`` (ownership/authority.py, ``admit``): a command of the owner under an epoch she no
  longer holds is admitted.
"""

from __future__ import annotations

__all__ = ["KINDS", "check"]

KINDS = ("reset", "double-owner", "stale-command")


def check(plant: str) -> str:
    """``plant`` itself when it is ``""`` (no defect) or one of :data:`KINDS`; ``ValueError`` naming them else."""
    if plant and plant not in KINDS:
        raise ValueError(f"unknown planted defect {plant!r}: expected one of {', '.join(KINDS)}")
    return plant
