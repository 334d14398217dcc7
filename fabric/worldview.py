"""One world for everyone: the union of the descriptions its sims serve (``rf/{world}/srv/world``).

Several sims may serve one world, each the authority of its own robots (docs/sim.md, "Several sims, one
world"); each answers ``srv/world`` with its part. :func:`union` joins the parts into one
:class:`~fabric.interfaces.WorldInfo` (pure), every robot carrying the sim that is its authority
(``RobotInfo.sim``); :func:`describe` asks every sim and returns the union, so the user API, the CLI and
tools never need to know which sim runs a robot.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Iterable

from fabric import keys
from fabric.interfaces import RobotInfo, WorldInfo

if TYPE_CHECKING:
    from fabric.session import Fabric

__all__ = ["union", "describe"]


def union(parts: Iterable[tuple[str, WorldInfo]]) -> WorldInfo:
    """One description from ``(source sim, its part)`` pairs: every robot once (the part of the higher term
    when two sims describe it: a primary that lost it has not noticed yet), each with its sim; the scene
    objects, timestep and rates of the part that describes the objects (the objects' authority, the world's
    first sim), else of the first part by sim id. Raises ``ValueError`` when there is no part."""
    parts = sorted(((src or p.header.source, p) for src, p in parts), key=lambda sp: sp[0])
    if not parts:
        raise ValueError("no world description to join")
    robots: dict[str, tuple[int, RobotInfo]] = {}
    for src, p in parts:
        for r in p.robots:
            term = p.header.term
            if r.id not in robots or term > robots[r.id][0]:
                robots[r.id] = (term, replace(r, sim=r.sim or src))
    base = next((p for _, p in parts if p.objects), parts[0][1])
    if len(parts) == 1 and all(r.sim for r in base.robots):
        return base
    return replace(base, robots=tuple(r for _, (_, r) in sorted(robots.items())))


def describe(fab: Fabric, *, timeout: float = 2.0) -> WorldInfo:
    """Every sim's part of ``fab``'s world, joined (:func:`union`). Raises the query's ``ServiceError`` when no
    sim answers (``NoReply``) or every one refuses (``Refused``)."""
    replies = fab.rpc.query(keys.srv(fab.world, "world"), timeout=timeout, expected=WorldInfo, all_replies=True)
    return union((rep.source, rep.message) for rep in replies)
