"""The robot kinds' one table: what every peer may assume of a robot from its kind (``RobotInfo.kind``).

A kind is part of the protocol (the description's ``[robot] kind``, the wire's ``RobotInfo.kind``): every peer
that shows, drives, plans for or mirrors robots reads it. Code does not compare a kind with a literal name
(``kind == "arm"``); it asks the kind's facts here (``facts(kind).chain``: does it have an arm's joints and a
flange?), so that a new kind is a row of :data:`KINDS` and its classes in the layers' registries, not a hunt
through the peers (docs/howto.md, "A new robot kind"; tests/robots/test_kinds.py fails on a comparison outside this table).

What a kind does in one layer is registered in that layer, keyed by the kind's name: the sim's built-in class
(``sim_peer.physics.registry.BUILTIN``), the user API's handle (a ``user_peer.robot.Robot`` subclass with its ``kind``,
found by ``Robot.for_kind``); the rest of each layer reads the facts.
This module is pure data: it imports nothing of the project, so every layer above ``fabric`` may read it.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["KINDS", "NAMES", "UNKNOWN", "RobotKind", "UnknownKind", "facts", "robot_kind"]


class UnknownKind(ValueError):
    """A kind that no row of :data:`KINDS` names; the text lists the kinds there are."""


@dataclass(frozen=True, slots=True)
class RobotKind:
    """The facts of one robot kind that the peers branch on.

    ``chain``: an arm, a chain of joints ending at a flange: commanded by joint targets and trajectories, its
    ``pose`` stream is its flange's, IK/FK/Jacobian serve it, other sims mirror its links, it is drawn as links.
    ``base``: a planar mobile base: driven by twists, its ``pose`` is its place on the map (odometry), it plans
    paths, carries range sensors (scans, sonar), its joints are its wheels, its description needs ``[base]``
    and ``base_joints``. ``data_stream``: the stream that shows where it is and whether it is still.
    """

    name: str
    data_stream: str
    chain: bool = False
    base: bool = False


KINDS: dict[str, RobotKind] = {
    k.name: k
    for k in (
        RobotKind("arm", data_stream="joints", chain=True),
        RobotKind("mobile", data_stream="pose", base=True),
    )
}
"""Every robot kind, by name, in the order peers list them (a console shows an arm's row before a base's)."""

NAMES: tuple[str, ...] = tuple(KINDS)
"""The kinds' names: what a description's ``[robot] kind`` and the wire's ``RobotInfo.kind`` may hold."""

UNKNOWN = RobotKind("", data_stream="joints")
"""The facts of a kind this peer does not know (or of a robot not described yet): none; its state in ``joints``."""


def robot_kind(name: str) -> RobotKind:
    """The kind named ``name``; :class:`UnknownKind` naming the kinds there are for any other name."""
    k = KINDS.get(name)
    if k is None:
        raise UnknownKind(f"unknown robot kind {name!r}: expected one of {', '.join(NAMES)}")
    return k


def facts(name: str) -> RobotKind:
    """The kind named ``name``, or :data:`UNKNOWN` (no facts) for a kind not in the table or ``""``: for a peer
    that shows what it can of a robot it does not fully know (a recording's robot not yet described)."""
    return KINDS.get(name, UNKNOWN)
