"""Whether a sim may take a step of a robot's move now: a pure core.

:class:`sim_peer.shards.moving.MoveService` asks it before each step of a move (:mod:`sim_peer.shards.handoff` holds the
protocol and its other pure helpers: the move's term, the fetch's and the take-back's refusals); it passes what the
host holds now (its role, its robots, the robots it handed out, the live sims, its term) as values and gets a
refusal's reason back ('' : go on). No zenoh, no lock, no clock, no message types.

The rules:

- only a serving primary that can rebuild its world, and has no standbys, moves robots in or out (a replicated
  shard's standbys would not follow the move);
- a source hands out a robot it serves, not already on its way, not its last one, to another live sim; it hands it
  out only if nothing changed while the target was asked (its term, the robot still its own and still here);
- a target takes in a robot it does not serve yet, at a term not below its own;
- a robot handed out is kept until its target serves it at the move's term or later (its joints say so), or taken
  back when no target fetched it in time.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence

__all__ = ["mover_refusal", "move_out_refusal", "unchanged", "move_in_refusal", "served_there", "unclaimed"]


def mover_refusal(me: str, *, serving: bool, can_rebuild: bool, standbys: Sequence[str]) -> str:
    """Why sim ``me`` may not move robots in or out now ('' : it may)."""
    if not serving:
        return f"sim {me} is not serving (a standby, or taking over)"
    if not can_rebuild:
        return f"sim {me} cannot rebuild its world (a sim of robofabric sim moves robots)"
    if standbys:
        return f"sim {me} has standbys ({', '.join(standbys)}): moving a robot of a replicated shard is not supported"
    return ""


def move_out_refusal(
    rid: str,
    to: str,
    me: str,
    *,
    robots: Collection[str],
    handed_out: Collection[str],
    live: Collection[str],
    world: str,
) -> str:
    """Why source ``me`` may not hand ``rid`` out to ``to`` ('' : it may ask ``to``)."""
    if rid not in robots:
        return f"sim {me} does not serve robot {rid}"
    if rid in handed_out:
        return f"robot {rid} is being moved already"
    if len(robots) < 2:
        return f"robot {rid} is sim {me}'s last robot: stop that sim and start {rid} on another instead"
    if to == me or to not in live:
        return f"sim {to} is not another live sim of world {world!r}: {rid} stays with sim {me}"
    return ""


def unchanged(rid: str, *, term: int, asked_at_term: int, robots: Collection[str], handed_out: Collection[str]) -> bool:
    """Whether the source is as it was when it asked its target: the same term, ``rid`` still served and not on its
    way (a move of its own that finished meanwhile, or a take-over, asks again)."""
    return term == asked_at_term and rid in robots and rid not in handed_out


def move_in_refusal(rid: str, me: str, *, term: int, my_term: int, robots: Collection[str]) -> str:
    """Why target ``me`` may not take ``rid`` in at ``term`` ('' : it may)."""
    if rid in robots:
        return f"sim {me} already serves {rid}"
    if term < my_term:
        return f"move term {term} is below sim {me}'s term {my_term}: ask again"
    return ""


def served_there(kept_to: str, kept_term: int, sim: str, term: int) -> bool:
    """Whether ``sim`` serving a robot at ``term`` ends what its source kept of it (handed to ``kept_to`` at
    ``kept_term``): that sim is its target, at the move's term or later."""
    return kept_to == sim and term >= kept_term


def unclaimed(*, closed: bool, kept_move: str | None, move_id: str, fetched: bool) -> bool:
    """Whether a robot handed out in move ``move_id`` is still waiting for its target when its timer fires (``kept_move``
    None: it is no longer kept): the source serves it again then."""
    return not closed and kept_move == move_id and not fetched
