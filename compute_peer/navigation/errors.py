"""The one error type of mapping and planning.

Every refusal (goal outside the map, start in an obstacle, empty map, no path)
is a :class:`NavigationError` whose message is the reason a user reads; the
service turns it into a :class:`fabric.interfaces.ServiceError` with the same text.
"""

from __future__ import annotations


class NavigationError(ValueError):
    """A map or plan request cannot be satisfied; ``str(exc)`` says why."""


class StuckAtStart(NavigationError):
    """Hybrid A* could not take one step from the start's heading (every first arc touches an obstacle); a base
    that turns on the spot may still leave facing another way (:func:`compute_peer.navigation.planner.plan_path`)."""
