"""The ROS 2 bridge's trust boundary: which robots it takes commands for, and how far DDS discovery reaches.

A ROS 2 domain has no logins: any node that discovers the bridge may publish on its topics, and the bridge
would send what it hears in its own login's name. So by default the bridge only publishes; it takes
``cmd_vel`` / ``joint_command`` / ``joint_trajectory`` only for the robots named with ``--drive`` (and then only
while its login owns them, as for any user). Discovery stays on this host unless the user set
``ROS_AUTOMATIC_DISCOVERY_RANGE`` or asks with ``--discovery``: a bridge does not offer a class's robots to the
LAN's DDS domain by accident. The bridge says both at start (:func:`boundary_lines`). Pure: the environment is
passed in, and what to set comes back.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Collection, Mapping

__all__ = ["Discovery", "discovery", "boundary_lines", "RANGES", "RANGE_VAR"]

RANGE_VAR = "ROS_AUTOMATIC_DISCOVERY_RANGE"
RANGES = ("localhost", "subnet", "off", "system_default")
"""``--discovery``'s values: those of ROS 2's ``ROS_AUTOMATIC_DISCOVERY_RANGE`` (Iron and later), lower case."""


@dataclass(frozen=True, slots=True)
class Discovery:
    """How far the bridge's DDS discovery reaches, and why."""

    range: str  # one of RANGES
    source: str  # "default" (this bridge chose it), "environment" (the user set it), "option" (--discovery)
    set_env: Mapping[str, str] = field(default_factory=dict)  # variables to set before rclpy starts


def discovery(environ: Mapping[str, str], option: str | None) -> Discovery:
    """The discovery range: ``option`` (``--discovery``) if given; else the user's ``ROS_AUTOMATIC_DISCOVERY_RANGE``;
    else this host only. Raises ValueError for a value ROS 2 does not know."""
    if option is not None:
        value = option.strip().lower()
        if value not in RANGES:
            raise ValueError(f"--discovery must be one of {', '.join(RANGES)}, not {option!r}")
        return Discovery(value, "option", {RANGE_VAR: value.upper()})
    if environ.get(RANGE_VAR, "").strip():
        return Discovery(environ[RANGE_VAR].strip().lower(), "environment")
    return Discovery("localhost", "default", {RANGE_VAR: "LOCALHOST"})


def boundary_lines(user: str, drive: Collection[str], domain: str, found: Discovery) -> list[str]:
    """What the bridge says at start: whom it takes commands from, for which robots, and how far it is seen."""
    reach = {
        "localhost": "this host only",
        "subnet": "the local network (multicast)",
        "off": "no automatic discovery",
        "system_default": "the middleware's default",
    }.get(found.range, found.range)
    why = {
        "default": "the bridge's default; --discovery subnet opens it",
        "environment": f"{RANGE_VAR} as set",
        "option": "--discovery",
    }[found.source]
    out = [f"DDS discovery: {reach} ({why}); ROS domain {domain}"]
    if not drive:
        out.append("commands: none taken (publishing only); --drive ROBOT takes cmd_vel and joint commands for it")
    else:
        who = (
            "any node on this host"
            if found.range == "localhost"
            else f"any node that discovers it on ROS domain {domain}"
        )
        out.append(
            f"commands: taken for {', '.join(sorted(drive))} only, from {who} (ROS 2 has no logins), "
            f"sent as {user!r} while {user!r} owns the robot"
        )
    return out
