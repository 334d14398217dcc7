"""What a ROS 2 ``cmd_vel`` asks of a base, checked before it is sent: refused, clamped, or as it is.

A ``geometry_msgs/Twist`` (or ``TwistStamped``, ``--cmd-vel-stamped``) carries any float. The bridge refuses
what no base can mean: a value that is not finite (NaN, inf: a controller's division by zero), or more than
``ABSURD`` times the base's limit (a unit slip: mm/s, deg/s). What is above the limit but plausible is sent, and
the sim clamps it to the base's ``max_speed`` / ``max_omega``; the bridge says so on /rosout, with the limits,
so the ROS user learns why her 2 m/s became 1. Pure: the limits are the world description's (``BaseInfo``).
"""

from __future__ import annotations

import math
from typing import Any

from user_peer.ros2.commands import CommandError

__all__ = ["ABSURD", "base_limits", "twist_check"]

ABSURD = 10.0
"""A command more than this many times the base's limit is refused rather than clamped (a unit mistake)."""


def twist_check(v: float, omega: float, base: Any | None) -> str:
    """Check ``(v m/s, omega rad/s)`` against ``base`` (a ``BaseInfo``; None: limits unknown, only finiteness is
    checked). :class:`CommandError` for a command to refuse; else a note for /rosout when the sim will clamp it
    (empty when it is within the limits)."""
    if not (math.isfinite(v) and math.isfinite(omega)):
        raise CommandError(f"cmd_vel linear.x {v} m/s, angular.z {omega} rad/s is not finite")
    if base is None:
        return ""
    notes = []
    for what, value, limit, unit in (
        ("linear.x", v, base.max_speed, "m/s"),
        ("angular.z", omega, base.max_omega, "rad/s"),
    ):
        if limit > 0 and abs(value) > ABSURD * limit:
            raise CommandError(
                f"cmd_vel {what} {value:g} {unit} is more than {ABSURD:g} times the base's limit "
                f"{limit:g} {unit} (a unit mistake?)"
            )
        if limit > 0 and abs(value) > limit:
            notes.append(
                f"{what} {value:g} {unit} clamped by the sim to {math.copysign(limit, value):g} {unit} (the base's limit)"
            )
    return "; ".join(notes)


def base_limits(info: Any, robot: str) -> Any | None:
    """``robot``'s ``BaseInfo`` in the world description ``info`` (None: no description, no such robot, no base)."""
    for r in getattr(info, "robots", ()) or ():
        if r.id == robot:
            return r.base
    return None
