"""Planted defects, for proving the soak's checker is not vacuous. TEST-ONLY: never set in a real world.

``ROBOFABRIC_PLANT`` names one defect; it is read here once, at import, and nowhere else. Unset (or
empty) every hook is inert: :func:`planted` is False for every kind. ``robofabric bench soak --plant KIND``
sets it in the sims it starts, and the checker must then report a violation (robofabric/soak/checker.py;
tests/robofabric/soak/test_soak_plants.py). The hooks, one line each:

* ``reset`` (sim_peer/following.py, ``catch_up``): a standby taking the world over puts its robots back at
  their spawn pose instead of where the old authority left them;
* ``double-owner`` (ownership/state.py, a take-over of a still robot): the new owner gets the old owner's
  epoch, so two owners hold one epoch;
* ``stale-command`` (ownership/authority.py, ``admit``): a command of the owner under an epoch she no
  longer holds is admitted.
"""

from __future__ import annotations

import os

__all__ = ["KINDS", "PLANT", "planted"]

KINDS = ("reset", "double-owner", "stale-command")
PLANT = os.environ.get("ROBOFABRIC_PLANT", "")


def planted(kind: str) -> bool:
    """Whether the defect ``kind`` is planted in this process (False unless ROBOFABRIC_PLANT names it)."""
    return bool(PLANT) and PLANT == kind
